"""Odometry priors in BA: one relative prior per consecutive keyframe pair, one absolute prior per keyframe,
and the priors (not a held keyframe) keep the model where the odometry put it."""

import numpy as np
import pytest

from cama_pipeline.sfm.config import SfmConfig
from cama_pipeline.sfm.guided import reconstruct_views
from tests.sfm.sfm_fixture import SfmInputs, relative_pose_errors

pytestmark = pytest.mark.slow  # the shared SfM inputs take ~30 s to build (pairs, features)


def test_priors_chain_consecutive_keyframes_and_hold_the_model_near_the_odometry(
    sfm_inputs: SfmInputs,
) -> None:
    views = sfm_inputs.longest_drive()
    config = SfmConfig.preset("rigid", odometry_priors=True)
    result = reconstruct_views(views, sfm_inputs.database, sfm_inputs.image_dir, config)
    (adjustment,) = result.report["iterations"]
    keyframes = len({v.frame_index for v in views if v.name in result.world_from_ego})
    assert adjustment["priors"] == {"relative": keyframes - 1, "absolute": keyframes}
    odometry = {v.name: v.world_from_ego for v in views}
    offsets = [result.world_from_ego[n][:3, 3] - odometry[n][:3, 3] for n in result.world_from_ego]
    assert np.linalg.norm(np.mean(offsets, axis=0)) < 0.1  # the gauge is the odometry's, on average


def test_plain_ba_priors_chain_each_camera_separately(sfm_inputs: SfmInputs) -> None:
    views = sfm_inputs.longest_drive()
    config = SfmConfig.preset("plain", odometry_priors=True)
    result = reconstruct_views(views, sfm_inputs.database, sfm_inputs.image_dir, config)
    (adjustment,) = result.report["iterations"]
    kept = [v for v in views if v.name in result.world_from_ego]
    channels = {v.channel for v in kept}
    assert adjustment["priors"]["absolute"] == len(kept)
    assert adjustment["priors"]["relative"] <= len(kept) - len(channels)


def test_priors_keep_the_odometrys_scale_along_the_drive(sfm_inputs: SfmInputs) -> None:
    views = sfm_inputs.longest_drive()
    anchor = next(v.name for v in views if v.frame_index == 0 and v.channel == "CAM_FRONT")
    truth = sfm_inputs.true_world_from_ego
    errors = {}
    for priors in (False, True):
        config = SfmConfig.preset("rigid", odometry_priors=priors)
        result = reconstruct_views(views, sfm_inputs.database, sfm_inputs.image_dir, config)
        errors[priors] = relative_pose_errors(result.world_from_ego, truth, anchor)[0]
    assert errors[True] < 0.05 and errors[True] < errors[False], errors
