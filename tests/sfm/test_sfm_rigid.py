"""Rigid BA: every keyframe's cameras keep the calibrated relative transforms; plain BA lets them drift."""

from dataclasses import replace

import numpy as np
import pycolmap
import pytest

from cama_pipeline.cameras import CameraView
from cama_pipeline.sfm.config import SfmConfig
from cama_pipeline.sfm.guided import reconstruct_views, refined_views
from cama_pipeline.sfm.model import matrix_from_rigid
from tests.sfm.sfm_fixture import SfmInputs

pytestmark = pytest.mark.slow  # the shared SfM inputs take ~30 s to build (pairs, features)


def largest_rig_deviation(reconstruction: pycolmap.Reconstruction, views: list[CameraView]) -> float:
    """Largest difference between a keyframe camera's pose relative to CAM_FRONT after BA and before
    (calibration plus the odometry's motion between the cameras' capture times)."""
    worst = 0.0
    for key in {(v.scene, v.frame_index) for v in views}:
        cameras = {
            v.channel: (v, reconstruction.find_image_with_name(v.name))
            for v in views
            if (v.scene, v.frame_index) == key
        }
        front_view, front = cameras["CAM_FRONT"]
        if front is None or not front.has_pose:
            continue
        front_from_world = matrix_from_rigid(front.cam_from_world())
        for view, image in cameras.values():
            if image is None or not image.has_pose:
                continue
            cam_from_front = matrix_from_rigid(image.cam_from_world()) @ np.linalg.inv(front_from_world)
            expected = np.linalg.inv(view.world_from_cam) @ front_view.world_from_cam
            worst = max(worst, float(np.abs(cam_from_front - expected).max()))
    return worst


def test_rigid_ba_keeps_each_keyframes_cameras_fixed_relative_to_each_other(sfm_inputs: SfmInputs) -> None:
    """Placed by the rigid gauge fit: the scaled one scales the whole model after BA, rig baselines included."""
    views = sfm_inputs.longest_drive()
    config = SfmConfig.preset("rigid", odometry_priors=False, gauge_fit_scale=False)
    result = reconstruct_views(views, sfm_inputs.database, sfm_inputs.image_dir, config)
    assert result.report["iterations"][0]["max_move_m"] > 1e-4  # BA did move the keyframes
    assert largest_rig_deviation(result.reconstruction, views) < 1e-6


def test_plain_ba_moves_cameras_of_one_keyframe_independently(sfm_inputs: SfmInputs) -> None:
    views = sfm_inputs.longest_drive()
    result = reconstruct_views(views, sfm_inputs.database, sfm_inputs.image_dir, SfmConfig.preset("plain"))
    assert result.reconstruction.num_frames() == result.reconstruction.num_images()
    assert largest_rig_deviation(result.reconstruction, views) > 1e-5


def test_keyframes_that_ba_moves_too_far_are_flagged_and_dropped(sfm_inputs: SfmInputs) -> None:
    views = sfm_inputs.longest_drive()
    last = max(v.frame_index for v in views)
    shifted = np.eye(4)
    shifted[1, 3] = 0.5
    moved = [
        replace(v, world_from_ego=v.world_from_ego @ shifted) if v.frame_index == last else v for v in views
    ]
    config = SfmConfig.preset("rigid", odometry_priors=False, max_camera_shift_m=0.2)
    result = reconstruct_views(moved, sfm_inputs.database, sfm_inputs.image_dir, config)
    dropped = {v.name for v in views if v.frame_index == last}
    assert dropped <= set(result.flagged)
    assert all("moved" in result.report["flagged_images"][name] for name in dropped)
    assert not dropped & {v.name for v in refined_views(result, moved)}


def test_refined_extrinsics_share_one_rig_across_keyframes(sfm_inputs: SfmInputs) -> None:
    views = sfm_inputs.longest_drive()
    config = SfmConfig.preset("rigid", refine_extrinsics=True)
    result = reconstruct_views(views, sfm_inputs.database, sfm_inputs.image_dir, config)
    reconstruction = result.reconstruction
    assert reconstruction.num_rigs() == 1 and reconstruction.num_cameras() == 6
    assert reconstruction.num_frames() == len({v.frame_index for v in views})
    assert result.report["mean_reprojection_error_px"] < 1.0
