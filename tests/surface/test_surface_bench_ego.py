"""`bench/surface.py`'s ego-frame figures: the tiny site's own truth scores perfectly in the ego frames of its key
frames, still when the raster and the poses are shifted alike (a site placed by a shifted gauge), and not when
only the raster is."""

from dataclasses import replace

import numpy as np
import pytest

from bench.surface import ego_frame_figures
from cama_pipeline.bev import BevRasters
from cama_pipeline.cameras import CameraView
from cama_pipeline.semantics import ROAD_SURFACE_IDS
from cama_pipeline.synthetic.truth_grid import TrueGround, cell_centres, stored_truth
from tests.conftest import GeneratedSite

SHIFT_M = 0.1


def keyframe_views(truth: BevRasters, count: int = 4) -> list[CameraView]:
    """One front camera per key frame, standing on road cells of the truth along the site, heading east."""
    road = np.flatnonzero(np.isin(truth.require("semantic"), ROAD_SURFACE_IDS).ravel())
    picks = road[np.linspace(0, len(road) - 1, count + 2).astype(int)[1:-1]]
    xy = cell_centres(truth.georeference)[picks]
    views = []
    for index, (cell, (x, y)) in enumerate(zip(picks, xy, strict=True)):
        pose = np.eye(4)
        pose[:3, 3] = [x, y, truth.require("elevation").ravel()[cell]]
        views.append(
            CameraView(
                f"samples/CAM_FRONT/{index}.jpg",
                f"token-{index}",
                "scene-0001",
                "CAM_FRONT",
                index,
                index * 500_000,
                pose,
                np.eye(4),
                np.eye(3),
                256,
                144,
            )
        )
    return views


def shifted(truth: BevRasters) -> BevRasters:
    geo = truth.georeference
    moved = geo.model_copy(update={"origin_xy": (geo.origin_xy[0] + SHIFT_M, geo.origin_xy[1])})
    return replace(truth, georeference=moved)


def moved_views(views: list[CameraView]) -> list[CameraView]:
    out = []
    for view in views:
        pose = view.world_from_ego.copy()
        pose[0, 3] += SHIFT_M
        out.append(replace(view, world_from_ego=pose))
    return out


@pytest.fixture(scope="module")
def truth(tiny_site: GeneratedSite) -> BevRasters:
    return stored_truth(tiny_site.result.out_dir)


@pytest.fixture(scope="module")
def ground(tiny_site: GeneratedSite) -> TrueGround:
    return TrueGround.of(tiny_site.result.out_dir)


def test_the_truth_scores_perfectly_in_its_own_ego_frames(ground: TrueGround, truth: BevRasters) -> None:
    views = keyframe_views(truth)
    step = np.zeros(truth.georeference.shape, np.float32)
    figures = ego_frame_figures(ground, truth, step, views, views)
    road = figures["heights_road"]
    assert road["keyframes"] == 4 and road["pairs"] > 1000
    assert road["rmse_cm"] < 0.01 and road["same_pairs_in_global_frame"]["rmse_cm"] < 0.01
    assert figures["iou"]["ego"]["road"] == 1.0 and figures["iou"]["ego"]["lane_marking"] == 1.0


def test_a_shift_the_raster_and_poses_share_cancels_and_an_unshared_one_does_not(
    ground: TrueGround, truth: BevRasters
) -> None:
    views = keyframe_views(truth)
    step = np.zeros(truth.georeference.shape, np.float32)
    ours = shifted(truth)
    alike = ego_frame_figures(ground, ours, step, moved_views(views), views)
    assert alike["iou"]["ego"]["lane_marking"] == pytest.approx(1.0, abs=1e-6)
    assert alike["iou"]["same_pairs_in_global_frame"]["lane_marking"] < 0.9
    assert alike["heights_road"]["rmse_cm"] < 0.01
    alone = ego_frame_figures(ground, ours, step, views, views)
    assert alone["iou"]["ego"]["lane_marking"] < 0.9
    assert alone["iou"]["ego"]["curb"] < alike["iou"]["ego"]["curb"]
