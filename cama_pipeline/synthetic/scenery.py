"""3D objects of the site as oriented boxes: buildings, poles, parked cars, moving traffic and the ego trunk."""

from dataclasses import dataclass
from enum import IntEnum

import numpy as np
import torch
from shapely import affinity
from shapely.geometry import LineString, Point, Polygon, box
from shapely.ops import unary_union

from cama_pipeline.synthetic.layout import RoadLayout
from cama_pipeline.synthetic.terrain import Terrain

CAR_SIZE_M = (4.5, 1.85, 1.5)
VAN_SIZE_M = (5.4, 2.0, 2.2)
TRUNK_CENTER_EGO = (-0.45, 0.0, 0.72)
"""The ego vehicle's trunk in the ego frame (origin on the ground under the rear axle): seen by CAM_BACK."""
TRUNK_HALF_EGO = (0.5, 0.88, 0.43)


class BoxKind(IntEnum):
    """What a box is; decides its texture and its semantic label."""

    BUILDING = 0
    POLE = 1
    CAR = 2
    EGO = 3


@dataclass(frozen=True)
class Boxes:
    """Oriented boxes in layout-local metres."""

    center: np.ndarray  # (M, 3)
    half: np.ndarray  # (M, 3) half extents along the box's own x (length), y (width), z (height)
    rotation: np.ndarray  # (M, 3, 3) layout_from_box
    kind: np.ndarray  # (M,) BoxKind
    color: np.ndarray  # (M, 3) RGB in [0, 1]

    def __len__(self) -> int:
        return int(self.center.shape[0])

    @staticmethod
    def empty() -> "Boxes":
        """No boxes."""
        return Boxes(
            np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3, 3)), np.zeros(0, np.int64), np.zeros((0, 3))
        )

    def concat(self, other: "Boxes") -> "Boxes":
        """Both sets of boxes."""
        return Boxes(
            np.vstack([self.center, other.center]),
            np.vstack([self.half, other.half]),
            np.concatenate([self.rotation, other.rotation]),
            np.concatenate([self.kind, other.kind]),
            np.vstack([self.color, other.color]),
        )


def _ground_z(terrain: Terrain, x: float, y: float) -> float:
    return float(
        terrain.height(torch.tensor([x], dtype=torch.float64), torch.tensor([y], dtype=torch.float64))[0]
    )


def _footprint(cx: float, cy: float, length: float, width: float, yaw: float) -> Polygon:
    return affinity.rotate(
        box(cx - length / 2, cy - width / 2, cx + length / 2, cy + width / 2), yaw, use_radians=True
    )


def build_static_scenery(layout: RoadLayout, terrain: Terrain, rng: np.random.Generator) -> Boxes:
    """Buildings along every road, poles on the sidewalks, a few cars parked in the east bike lanes."""
    rows: list[
        tuple[tuple[float, float, float], tuple[float, float, float], float, BoxKind, tuple[float, ...]]
    ] = []
    cfg = layout.config
    keep_clear = unary_union([layout.road, layout.sidewalk]).buffer(cfg.building_setback_m - 0.1)
    taken: list[Polygon] = []
    centerlines = [(layout.main_centerline, layout.main_half_width())]
    centerlines += [(c, layout.cross_half_width()) for c in layout.cross_centerlines]
    for line, half in centerlines:
        for side in (-1.0, 1.0):
            s = float(rng.uniform(0, 6))
            while s < line.length:
                length, depth, height = rng.uniform(8, 16), rng.uniform(7, 12), rng.uniform(5, 18)
                offset = side * (half + cfg.sidewalk_width_m + cfg.building_setback_m + depth / 2)
                placed = _place_along(line, s + length / 2, offset)
                if placed is not None:
                    (cx, cy), yaw = placed
                    foot = _footprint(cx, cy, length, depth, yaw)
                    if not foot.intersects(keep_clear) and not any(foot.intersects(t) for t in taken):
                        taken.append(foot)
                        z0 = min(_ground_z(terrain, x, y) for x, y in foot.exterior.coords) - 0.3
                        tint = rng.uniform(0.45, 0.85) * np.array(
                            [1.0, rng.uniform(0.85, 1.0), rng.uniform(0.7, 0.95)]
                        )
                        rows.append(
                            (
                                (cx, cy, z0 + height / 2),
                                (length / 2, depth / 2, height / 2),
                                yaw,
                                BoxKind.BUILDING,
                                tuple(tint),
                            )
                        )
                s += length + rng.uniform(1.0, 6.0)
            for s in np.arange(rng.uniform(3, 10), line.length, 18.0):
                placed = _place_along(line, float(s), side * (half + 0.7))
                if placed is not None and layout.sidewalk.contains(Point(placed[0])):
                    (px, py), _ = placed
                    h = rng.uniform(5.0, 7.5)
                    rows.append(
                        (
                            (px, py, _ground_z(terrain, px, py) + h / 2),
                            (0.09, 0.09, h / 2),
                            0.0,
                            BoxKind.POLE,
                            (0.42, 0.43, 0.45),
                        )
                    )
    rows.extend(_parked_cars(layout, terrain, rng))
    return _boxes_from_rows(rows)


def _parked_cars(layout: RoadLayout, terrain: Terrain, rng: np.random.Generator) -> list:
    """Cars parked in the bike lane of the main road east of the junctions (they occlude the road)."""
    cfg = layout.config
    x_start = max(cfg.cross_road_x_m) + layout.cross_half_width() + 20.0
    offset = -(cfg.main_lanes_per_direction * cfg.lane_width_m + cfg.bike_lane_width_m / 2 + 0.1)
    lane = layout.main_centerline.offset_curve(offset)
    rows = []
    s = lane.project(Point(x_start, offset))
    for _ in range(3):
        placed = _place_along(lane, s, 0.0)
        if placed is None:
            break
        (cx, cy), yaw = placed
        rows.append(_car_row(terrain, cx, cy, yaw, CAR_SIZE_M, rng))
        s += CAR_SIZE_M[0] + rng.uniform(1.0, 8.0)
    return rows


def _car_row(
    terrain: Terrain,
    cx: float,
    cy: float,
    yaw: float,
    size: tuple[float, float, float],
    rng: np.random.Generator,
) -> tuple:
    color = tuple(
        rng.choice(
            [
                [0.7, 0.1, 0.1],
                [0.1, 0.2, 0.6],
                [0.85, 0.85, 0.85],
                [0.15, 0.15, 0.15],
                [0.5, 0.55, 0.6],
                [0.2, 0.45, 0.25],
            ]
        )
        * rng.uniform(0.85, 1.1)
    )
    z = _ground_z(terrain, cx, cy) + 0.05 + size[2] / 2
    return ((cx, cy, z), (size[0] / 2, size[1] / 2, size[2] / 2), yaw, BoxKind.CAR, color)


def _place_along(line: LineString, s: float, offset: float) -> tuple[tuple[float, float], float] | None:
    """Point `offset` to the left of `line` at arc length `s`, and the line's heading there; None past the end."""
    if s < 0 or s > line.length:
        return None
    p = np.array(line.interpolate(s).coords[0])
    q = np.array(line.interpolate(min(s + 0.5, line.length)).coords[0])
    if s + 0.5 > line.length:
        p, q = np.array(line.interpolate(s - 0.5).coords[0]), p
    d = (q - p) / max(np.linalg.norm(q - p), 1e-9)
    base = np.array(line.interpolate(s).coords[0])
    left = np.array([-d[1], d[0]])
    xy = base + offset * left
    return (float(xy[0]), float(xy[1])), float(np.arctan2(d[1], d[0]))


def yaw_rotation(yaw: float) -> np.ndarray:
    """Rotation about z by `yaw` radians."""
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _boxes_from_rows(rows: list) -> Boxes:
    if not rows:
        return Boxes.empty()
    return Boxes(
        center=np.array([r[0] for r in rows], float),
        half=np.array([r[1] for r in rows], float),
        rotation=np.stack([yaw_rotation(r[2]) for r in rows]),
        kind=np.array([int(r[3]) for r in rows], np.int64),
        color=np.array([r[4] for r in rows], float),
    )


@dataclass(frozen=True)
class MovingVehicle:
    """A vehicle driving along a lane at constant speed from `start_s_m` at `start_time_us`."""

    lane: LineString
    start_s_m: float
    speed_mps: float
    start_time_us: int
    size_m: tuple[float, float, float]
    color: tuple[float, float, float]


def plan_traffic(
    layout: RoadLayout,
    ego_lane: str,
    ego_start_s_m: float,
    start_time_us: int,
    count: int,
    rng: np.random.Generator,
) -> tuple[MovingVehicle, ...]:
    """Vehicles in other lanes around the ego's start: some ahead in its direction, some oncoming."""
    others = [name for name in sorted(layout.lanes) if name != ego_lane]
    vehicles = []
    for _ in range(count):
        name = others[int(rng.integers(len(others)))]
        lane = layout.lanes[name]
        s0 = float(np.clip(ego_start_s_m + rng.uniform(-10, 45), 0, lane.length))
        size = VAN_SIZE_M if rng.uniform() < 0.25 else CAR_SIZE_M
        red, green, blue = (float(c) for c in rng.uniform(0.1, 0.9, size=3))
        color = (red, green, blue)
        vehicles.append(MovingVehicle(lane, s0, float(rng.uniform(4.0, 10.0)), start_time_us, size, color))
    return tuple(vehicles)


def traffic_boxes(vehicles: tuple[MovingVehicle, ...], terrain: Terrain, time_us: int) -> Boxes:
    """Boxes of the vehicles still on their lanes at `time_us`."""
    rows = []
    for v in vehicles:
        s = v.start_s_m + v.speed_mps * (time_us - v.start_time_us) * 1e-6
        placed = _place_along(v.lane, s, 0.0)
        if placed is None:
            continue
        (cx, cy), yaw = placed
        z = _ground_z(terrain, cx, cy) + 0.05 + v.size_m[2] / 2
        rows.append(((cx, cy, z), tuple(x / 2 for x in v.size_m), yaw, BoxKind.CAR, v.color))
    return _boxes_from_rows(rows)


def ego_trunk_box(layout_from_ego_R: np.ndarray, layout_from_ego_t: np.ndarray) -> Boxes:
    """The ego trunk as a box in the layout frame for one ego pose."""
    center = layout_from_ego_R @ np.asarray(TRUNK_CENTER_EGO) + layout_from_ego_t
    return Boxes(
        center[None],
        np.asarray(TRUNK_HALF_EGO)[None],
        layout_from_ego_R[None].copy(),
        np.array([int(BoxKind.EGO)]),
        np.array([[0.22, 0.24, 0.27]]),
    )
