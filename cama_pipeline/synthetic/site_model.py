"""Everything a generated site is made of, built deterministically from its config alone.

Render workers rebuild this from the config instead of receiving it, so each process holds its own copy
and no large arrays cross process boundaries.
"""

from dataclasses import dataclass

import numpy as np

from cama_pipeline.synthetic.atlas import build_atlas
from cama_pipeline.synthetic.config import SynthConfig
from cama_pipeline.synthetic.layout import RoadLayout, build_layout
from cama_pipeline.synthetic.render import View, World
from cama_pipeline.synthetic.rig import RigCamera, build_rig
from cama_pipeline.synthetic.routes import ClipPlan, plan_clips
from cama_pipeline.synthetic.scenery import (
    Boxes,
    MovingVehicle,
    build_static_scenery,
    ego_trunk_box,
    plan_traffic,
    traffic_boxes,
)
from cama_pipeline.synthetic.schedule import ClipSchedule, schedule_clip
from cama_pipeline.synthetic.shading import NoiseBank
from cama_pipeline.synthetic.terrain import Terrain

# Sub-seeds: each component draws from its own generator so adding draws to one never shifts another.
SEED_SCENERY, SEED_ROUTES, SEED_TRAFFIC, SEED_NOISE, SEED_EXPOSURE = 1, 2, 3, 4, 5


def sub_rng(seed: int, *stream: int) -> np.random.Generator:
    """An independent generator for one component (and optionally one item) of the site."""
    return np.random.default_rng([seed, *stream])


@dataclass(frozen=True)
class SyntheticSite:
    """A whole site: the world, the rig, the clips with their schedules, traffic and exposure."""

    config: SynthConfig
    layout: RoadLayout
    world: World
    rig: tuple[RigCamera, ...]
    clips: tuple[ClipPlan, ...]
    schedules: tuple[ClipSchedule, ...]
    traffic: tuple[tuple[MovingVehicle, ...], ...]
    exposures: tuple[float, ...]

    def view(self, clip_index: int, shot_index: int) -> tuple[View, np.ndarray, np.ndarray]:
        """The true camera view of one shot, with the true layout_from_ego rotation and translation."""
        clip = self.clips[clip_index]
        shot = self.schedules[clip_index].shots[shot_index]
        cam = next(c for c in self.rig if c.channel == shot.channel)
        R, t = clip.motion.interpolate(np.array([shot.timestamp_us]))
        R_ego, t_ego = R[0], t[0]
        view = View(
            R_ego @ cam.ego_from_cam_R, R_ego @ cam.ego_from_cam_t + t_ego, cam.K, cam.width_px, cam.height_px
        )
        return view, R_ego, t_ego

    def log_name(self, clip_index: int) -> str:
        """`log.logfile` of a clip (also the stem of its image file names)."""
        clip = self.clips[clip_index]
        return f"synth-{self.config.preset}-{clip.index + 1:04d}-{clip.kind}"

    def boxes_at(self, clip_index: int, time_us: int, R_ego: np.ndarray, t_ego: np.ndarray) -> Boxes:
        """Static scenery, the clip's traffic at `time_us` and the ego trunk."""
        moving = traffic_boxes(self.traffic[clip_index], self.world.terrain, time_us)
        return self.world.static_boxes.concat(moving).concat(ego_trunk_box(R_ego, t_ego))


def build_synthetic_site(cfg: SynthConfig) -> SyntheticSite:
    """Build the site of `cfg` (same config, same site, in every process)."""
    layout = build_layout(cfg.layout)
    terrain = Terrain(cfg.terrain)
    atlas = build_atlas(layout, cfg.ground_texel_m)
    static = build_static_scenery(layout, terrain, sub_rng(cfg.seed, SEED_SCENERY))
    world = World(
        terrain,
        atlas,
        static,
        NoiseBank(int(sub_rng(cfg.seed, SEED_NOISE).integers(2**31))),
        cfg.layout.curb_height_m,
        cfg.appearance,
    )
    rig = build_rig(cfg.camera)
    clips = tuple(plan_clips(cfg, layout, terrain, sub_rng(cfg.seed, SEED_ROUTES)))
    schedules = tuple(
        schedule_clip(c.start_time_us, c.duration_s, rig, cfg.clips.sweep_hz, cfg.clips.sample_hz)
        for c in clips
    )
    traffic = tuple(
        plan_traffic(
            layout,
            c.route.lane,
            c.start_s_m,
            c.start_time_us,
            cfg.clips.moving_vehicles_per_clip,
            sub_rng(cfg.seed, SEED_TRAFFIC, c.index),
        )
        for c in clips
    )
    exposure_rng = sub_rng(cfg.seed, SEED_EXPOSURE)
    gain = cfg.appearance.exposure_gain
    exposures = tuple(float(exposure_rng.uniform(0.93, 1.07)) * gain for _ in clips)
    return SyntheticSite(cfg, layout, world, rig, clips, schedules, traffic, exposures)
