"""The synthetic world meets the site spec: junction, crossings, curve, lanes, paint styles, curbs, grades."""

import numpy as np
import pytest
import torch

from cama_pipeline.synthetic.config import LayoutConfig, SynthConfig, TerrainConfig, preset
from cama_pipeline.synthetic.layout import build_layout
from cama_pipeline.synthetic.rig import build_rig
from cama_pipeline.synthetic.routes import plan_clips
from cama_pipeline.synthetic.terrain import Terrain


@pytest.mark.parametrize("name", ["tiny", "default", "large"])
def test_every_preset_builds_a_full_site(name):
    cfg = preset(name)
    layout = build_layout(cfg.layout)
    classes = [e.cls for e in layout.elements]
    assert classes.count("ped_crossing") == 4 * len(cfg.layout.cross_road_x_m), "zebra crossings on every arm"
    assert classes.count("boundary") >= 4
    styles = {(e.color, e.style) for e in layout.elements if e.cls == "divider"}
    assert {
        ("white", "dashed"),
        ("white", "solid"),
        ("yellow", "double_solid"),
        ("yellow", "dashed"),
    } <= styles
    assert layout.unpainted_dividers, "a lane edge without paint (the baseline map invents a divider there)"
    heading = np.degrees(
        np.arctan2(*np.diff(np.asarray(layout.main_centerline.coords)[-2:], axis=0)[0][::-1])
    )
    assert heading == pytest.approx(cfg.layout.curve_angle_deg, abs=1.0), "the main road curves"
    assert 2 <= cfg.layout.main_lanes_per_direction <= 3
    assert layout.sidewalk.area > 0 and 0.10 <= cfg.layout.curb_height_m <= 0.15


@pytest.mark.parametrize("name", ["tiny", "default", "large"])
def test_every_preset_plans_its_clips_within_their_routes(name):
    cfg = preset(name)
    layout = build_layout(cfg.layout)
    plans = plan_clips(cfg, layout, Terrain(cfg.terrain), np.random.default_rng(0))
    assert [plan.kind for plan in plans].count("moving") == len(cfg.clips.routes)
    moving = [plan for plan in plans if plan.kind == "moving"]
    travelled = [
        np.linalg.norm(np.diff(p.motion.global_from_ego_t[:, :2], axis=0), axis=1).sum() for p in moving
    ]
    assert min(travelled) > 0.8 * cfg.clips.speed_mps * cfg.clips.moving_duration_s


def test_terrain_rises_metres_with_grades_up_to_about_8_percent():
    cfg = preset("default")
    terrain = Terrain(cfg.terrain)
    x, y = torch.meshgrid(
        torch.linspace(-120, 140, 300, dtype=torch.float64),
        torch.linspace(-80, 90, 200, dtype=torch.float64),
        indexing="ij",
    )
    z = terrain.height(x, y)
    gx, gy = terrain.gradient(x, y)
    grade = torch.sqrt(gx**2 + gy**2)
    assert 2.0 < float(z.max() - z.min()) < 8.0
    assert 0.05 < float(grade.max()) <= cfg.terrain.max_grade
    dz_dx = (terrain.height(x + 1e-4, y) - terrain.height(x - 1e-4, y)) / 2e-4
    assert torch.allclose(dz_dx, gx, atol=1e-6), "analytic gradient matches the height"


def test_rig_is_the_six_nuscenes_cameras():
    rig = build_rig(preset("default").camera)
    assert [c.channel for c in rig] == [
        "CAM_FRONT",
        "CAM_FRONT_RIGHT",
        "CAM_BACK_RIGHT",
        "CAM_BACK",
        "CAM_BACK_LEFT",
        "CAM_FRONT_LEFT",
    ]
    for cam in rig:
        assert np.allclose(cam.ego_from_cam_R @ cam.ego_from_cam_R.T, np.eye(3), atol=1e-9)
        assert 1.4 < cam.ego_from_cam_t[2] < 1.7
    back = next(c for c in rig if c.channel == "CAM_BACK")
    assert back.ego_from_cam_R[:, 2][0] < -0.99, "CAM_BACK looks backwards"


@pytest.mark.parametrize(
    ("build", "field"),
    [
        (lambda: LayoutConfig(curb_height_m=0.3), "curb_height_m"),
        (lambda: LayoutConfig(lane_width_m=0.0), "lane_width_m"),
        (lambda: LayoutConfig(cross_road_x_m=()), "cross_road_x_m"),
        (lambda: TerrainConfig(rise_m=20.0), "max_grade"),
        (lambda: SynthConfig(ground_texel_m=0.0), "ground_texel_m"),
    ],
)
def test_bad_config_names_the_field(build, field):
    with pytest.raises(ValueError, match=field):
        build()
