"""The ego's drives: named routes through the site, speed profiles and the true 6-DoF motion of each clip."""

from dataclasses import dataclass
from typing import Literal

import numpy as np
import torch
from shapely.geometry import LineString, Point

from cama_pipeline.synthetic.config import SynthConfig
from cama_pipeline.synthetic.geometry2d import resample, rounded_polyline
from cama_pipeline.synthetic.layout import CORNER_RADIUS_M, STOP_GAP_M, RoadLayout
from cama_pipeline.synthetic.motion import TrueMotion
from cama_pipeline.synthetic.terrain import Terrain

ClipKind = Literal["moving", "stationary", "night"]
BASE_TIME_US = 1_538_000_000_000_000
"""Start of the first clip (an arbitrary nuScenes-like epoch)."""
MOTION_RATE_HZ = 100.0
MOTION_MARGIN_S = 0.5
"""True motion is sampled this long before and after the clip so sensors can look slightly outside it."""
MAX_LATERAL_ACCEL_MPS2 = 2.0
MAX_ACCEL_MPS2 = 1.5


@dataclass(frozen=True)
class Route:
    """A drivable path in driving direction and the arc length that should fall in the middle of the clip."""

    path: LineString
    lane: str
    mid_s_m: float


@dataclass(frozen=True)
class ClipPlan:
    """One scene to generate: where and when the ego drives, and its true motion in layout coordinates."""

    index: int
    kind: ClipKind
    route_name: str
    route: Route
    start_time_us: int
    duration_s: float
    start_s_m: float
    motion: TrueMotion

    @property
    def name(self) -> str:
        """nuScenes-style scene name."""
        return f"scene-{self.index + 1:04d}"


def named_route(name: str, layout: RoadLayout) -> Route:
    """The route of a name: east, west, north, south, south_turn_east, west_far, north_far."""
    cfg = layout.config
    xs = sorted(cfg.cross_road_x_m)
    x_far = xs[0]
    x_near = xs[-1]
    w = cfg.lane_width_m
    outer = cfg.main_lanes_per_direction - 1
    routes = {
        "east": ("main_east_0", (x_near, -0.5 * w)),
        "west": (f"main_west_{outer}", (x_near, (outer + 0.5) * w)),
        "west_far": ("main_west_0", (x_far, 0.5 * w)),
        "north": (f"cross{len(xs) - 1}_north_0", (x_near + 0.5 * w, 0.0)),
        "north_far": ("cross0_north_0", (x_far + 0.5 * w, 0.0)),
        "south": (f"cross{len(xs) - 1}_south_0", (x_near - 0.5 * w, 0.0)),
    }
    if name in routes:
        lane, mid = routes[name]
        path = layout.lanes[lane]
        return Route(path, lane, path.project(Point(mid)))
    if name == "south_turn_east":
        top = cfg.cross_road_half_length_m - 2.0
        corner = (x_near - 0.5 * w, -0.5 * w)
        end_x = layout.main_centerline.coords[0][0] + layout.main_centerline.length * 0.9
        path = rounded_polyline(
            np.array([(corner[0], top), corner, (min(end_x, x_near + 60.0), corner[1])]), 9.0
        )
        return Route(path, "main_east_0", path.project(Point(corner)))
    raise ValueError(f"unknown route {name!r}; known: {sorted(routes) + ['south_turn_east']}")


def stationary_route(layout: RoadLayout) -> tuple[Route, float]:
    """Westbound inner lane, waiting before the east crosswalk of the eastmost junction; returns route and s."""
    cfg = layout.config
    x_near = max(cfg.cross_road_x_m)
    stop_x = x_near + layout.cross_half_width() + CORNER_RADIUS_M + cfg.crosswalk_depth_m + STOP_GAP_M + 2.5
    path = layout.lanes["main_west_0"]
    s = path.project(Point(stop_x, 0.5 * cfg.lane_width_m))
    return Route(path, "main_west_0", s), s


def plan_clips(
    cfg: SynthConfig, layout: RoadLayout, terrain: Terrain, rng: np.random.Generator
) -> list[ClipPlan]:
    """Moving day clips over the configured routes, then one stationary and one night clip."""
    clips_cfg = cfg.clips
    plans: list[ClipPlan] = []
    specs: list[tuple[ClipKind, str, float]] = [
        ("moving", r, clips_cfg.moving_duration_s) for r in clips_cfg.routes
    ]
    specs += [
        ("stationary", "stationary", clips_cfg.stationary_duration_s),
        ("night", "south", clips_cfg.night_duration_s),
    ]
    for index, (kind, route_name, duration) in enumerate(specs):
        offset_s = 11 * 3600 if kind == "night" else index * 900
        start_us = BASE_TIME_US + int(offset_s * 1e6)
        if kind == "stationary":
            route, s0 = stationary_route(layout)
            speeds = None
        else:
            route = named_route(route_name, layout)
            s0 = route.mid_s_m - 0.5 * duration * clips_cfg.speed_mps
            s0 = float(
                np.clip(s0, 3.0, max(3.0, route.path.length - duration * clips_cfg.speed_mps * 1.25 - 3.0))
            )
            speeds = (clips_cfg.speed_mps, float(rng.uniform(0, 2 * np.pi)))
        motion = true_motion(route.path, s0, speeds, start_us, duration, terrain)
        plans.append(ClipPlan(index, kind, route_name, route, start_us, duration, s0, motion))
    return plans


def true_motion(
    path: LineString,
    start_s_m: float,
    speed: tuple[float, float] | None,
    start_time_us: int,
    duration_s: float,
    terrain: Terrain,
) -> TrueMotion:
    """Sample the ego's true pose at MOTION_RATE_HZ along `path` (standing still when `speed` is None)."""
    dt = 1.0 / MOTION_RATE_HZ
    times_s = np.arange(-MOTION_MARGIN_S, duration_s + MOTION_MARGIN_S + dt / 2, dt)
    pts = resample(path, 0.05)
    seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    arc = np.concatenate([[0.0], np.cumsum(seg)])
    heading = np.unwrap(np.arctan2(np.gradient(pts[:, 1]), np.gradient(pts[:, 0])))
    curvature = np.abs(np.gradient(heading, arc, edge_order=1))
    curvature = np.convolve(curvature, np.ones(41) / 41, mode="same")
    s = np.full(times_s.shape, start_s_m)
    if speed is not None:
        v_nom, phase = speed
        v = v_nom
        for k in range(1, len(times_s)):
            cap = np.sqrt(MAX_LATERAL_ACCEL_MPS2 / max(float(np.interp(s[k - 1], arc, curvature)), 1e-4))
            target = min(v_nom * (1.0 + 0.12 * np.sin(2 * np.pi * times_s[k] / 7.0 + phase)), cap)
            v += float(np.clip(target - v, -MAX_ACCEL_MPS2 * dt, MAX_ACCEL_MPS2 * dt))
            s[k] = s[k - 1] + v * dt
        if s[-1] > arc[-1]:
            raise ValueError(
                f"route of {path.length:.0f} m is too short for a {duration_s:.1f} s clip from s={start_s_m:.1f}"
            )
    x, y = np.interp(s, arc, pts[:, 0]), np.interp(s, arc, pts[:, 1])
    yaw = np.interp(s, arc, heading)
    R, z = _orientation_on_terrain(terrain, x, y, yaw)
    times_us = start_time_us + np.round(times_s * 1e6).astype(np.int64)
    return TrueMotion(times_us=times_us, global_from_ego_R=R, global_from_ego_t=np.stack([x, y, z], axis=1))


def _orientation_on_terrain(
    terrain: Terrain, x: np.ndarray, y: np.ndarray, yaw: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Rotations whose z axis is the terrain normal and x axis the heading tilted onto the slope; ground z."""
    xt, yt = torch.from_numpy(x), torch.from_numpy(y)
    z = terrain.height(xt, yt).numpy()
    gx, gy = (g.numpy() for g in terrain.gradient(xt, yt))
    up = np.stack([-gx, -gy, np.ones_like(gx)], axis=1)
    up /= np.linalg.norm(up, axis=1, keepdims=True)
    fwd = np.stack([np.cos(yaw), np.sin(yaw), gx * np.cos(yaw) + gy * np.sin(yaw)], axis=1)
    fwd -= (fwd * up).sum(axis=1, keepdims=True) * up
    fwd /= np.linalg.norm(fwd, axis=1, keepdims=True)
    left = np.cross(up, fwd)
    return np.stack([fwd, left, up], axis=2), z
