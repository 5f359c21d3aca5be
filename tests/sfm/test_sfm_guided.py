"""Guided SfM on the tiny site: perturbed odometry poses get closer to the truth; clips that cannot be
reconstructed raise SfmError naming them; bad inputs are named."""

import dataclasses
import math
import shutil
from pathlib import Path

import numpy as np
import pycolmap
import pytest

from cama_pipeline.cameras import CameraView
from cama_pipeline.sfm.config import SfmConfig
from cama_pipeline.sfm.errors import SfmError
from cama_pipeline.sfm.guided import reconstruct_views, refined_views
from tests.sfm.sfm_fixture import SfmInputs, pose_errors

pytestmark = pytest.mark.slow  # the shared SfM inputs take ~30 s to build (pairs, features)


def perturbed(views: list[CameraView], every: int, shift_m: float, turn_deg: float) -> list[CameraView]:
    """Views whose keyframes (all cameras together) with index % every == every - 1 are moved sideways
    by `shift_m` and turned by `turn_deg` about the vertical axis."""
    angle = math.radians(turn_deg)
    nudge = np.eye(4)
    nudge[:3, :3] = [[math.cos(angle), -math.sin(angle), 0], [math.sin(angle), math.cos(angle), 0], [0, 0, 1]]
    nudge[:3, 3] = [0.0, shift_m, 0.0]
    return [
        dataclasses.replace(v, world_from_ego=v.world_from_ego @ nudge)
        if v.frame_index % every == every - 1
        else v
        for v in views
    ]


def local_errors(
    world_from_ego: dict[str, np.ndarray], truth: dict[str, np.ndarray], previous: dict[str, str]
) -> tuple[float, float]:
    """`pose_errors` of each image's motion from the previous keyframe's image (name -> its predecessor):
    the perturbation itself, free of the slow drift that BA without odometry priors leaves along the clip."""
    names = [n for n in previous if n in world_from_ego and previous[n] in world_from_ego]
    return pose_errors(
        {n: np.linalg.inv(world_from_ego[previous[n]]) @ world_from_ego[n] for n in names},
        {n: np.linalg.inv(truth[previous[n]]) @ truth[n] for n in names},
    )


def test_guided_sfm_pulls_perturbed_keyframes_towards_the_truth(sfm_inputs: SfmInputs) -> None:
    views = sfm_inputs.longest_drive()
    moved = perturbed(views, every=3, shift_m=0.3, turn_deg=1.0)
    by_key = {(v.frame_index, v.channel): v.name for v in views}
    previous = {
        v.name: by_key[(v.frame_index - 1, v.channel)]
        for v in views
        if v.frame_index % 3 == 2 and (v.frame_index - 1, v.channel) in by_key
    }
    truth = sfm_inputs.true_world_from_ego
    before = local_errors({v.name: v.world_from_ego for v in moved}, truth, previous)
    result = reconstruct_views(
        moved, sfm_inputs.database, sfm_inputs.image_dir, SfmConfig.preset("rigid", odometry_priors=False)
    )
    after = local_errors(result.world_from_ego, truth, previous)
    assert before[0] > 0.2 and before[1] > 0.7
    assert after[0] < 0.5 * before[0] and after[1] < 0.1 * before[1], (before, after)
    report = result.report
    assert report["registered_images"] >= 0.8 * len(views) and report["points"] >= 100
    assert report["mean_reprojection_error_px"] < 1.0
    assert set(report["seconds"]) >= {"model", "triangulate", "refine"}
    refined = refined_views(result, moved)
    assert {v.name for v in refined} == set(result.world_from_ego)
    assert not set(result.flagged) & set(result.world_from_ego)


def test_progress_is_reported_per_phase(sfm_inputs: SfmInputs) -> None:
    seen: list[str] = []
    views = sfm_inputs.longest_drive()
    reconstruct_views(
        views,
        sfm_inputs.database,
        sfm_inputs.image_dir,
        SfmConfig.preset("iterative", max_iterations=2),
        progress=lambda phase, done, total: seen.append(phase),
    )
    assert {"model", "triangulate", "iterative BA"} <= set(seen)


def test_too_few_matches_raise_sfm_error_naming_the_clip(sfm_inputs: SfmInputs, tmp_path: Path) -> None:
    views = sfm_inputs.longest_drive()
    database = tmp_path / "database.db"
    shutil.copy(sfm_inputs.database, database)
    db = pycolmap.Database.open(str(database))
    try:
        db.clear_two_view_geometries()
    finally:
        db.close()
    with pytest.raises(SfmError, match=views[0].scene) as raised:
        reconstruct_views(views, database, sfm_inputs.image_dir, SfmConfig())
    assert "no verified matches" in str(raised.value)
    with pytest.raises(SfmError, match=f"{views[0].scene}: .* points"):
        reconstruct_views(views, sfm_inputs.database, sfm_inputs.image_dir, SfmConfig(min_points=10**6))


def test_bad_inputs_are_named(sfm_inputs: SfmInputs, tmp_path: Path) -> None:
    views = sfm_inputs.longest_drive()
    with pytest.raises(FileNotFoundError, match="missing.db"):
        reconstruct_views(views, tmp_path / "missing.db", sfm_inputs.image_dir, SfmConfig())
    with pytest.raises(ValueError, match="no views"):
        reconstruct_views([], sfm_inputs.database, sfm_inputs.image_dir, SfmConfig())
    stranger = dataclasses.replace(views[0], name="samples/CAM_FRONT/not-there.jpg")
    with pytest.raises(SfmError, match="not-there.jpg"):
        reconstruct_views([stranger, *views[1:]], sfm_inputs.database, sfm_inputs.image_dir, SfmConfig())
