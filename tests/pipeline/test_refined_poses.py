"""The SE(3) interpolation of `cama_pipeline.refined_poses` on synthetic poses, against hand computations."""

import math

import numpy as np

from cama_pipeline.data import Pose
from cama_pipeline.refined_poses import TimedPose, corrected_pose, interpolate_pose, slerp


def _about_z(angle_rad: float, translation: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> Pose:
    return Pose(np.array(translation), np.array([math.cos(angle_rad / 2), 0.0, 0.0, math.sin(angle_rad / 2)]))


def _assert_pose(actual: Pose, expected: Pose) -> None:
    np.testing.assert_allclose(actual.translation, expected.translation, atol=1e-12)
    np.testing.assert_allclose(actual.matrix(), expected.matrix(), atol=1e-12)


def test_slerp_halfway_is_half_the_angle() -> None:
    """Halfway between identity and 90 degrees about z is 45 degrees; the shorter arc of -q is taken."""
    q90 = _about_z(math.pi / 2).rotation
    np.testing.assert_allclose(slerp(np.array([1.0, 0, 0, 0]), q90, 0.5), _about_z(math.pi / 4).rotation)
    np.testing.assert_allclose(slerp(np.array([1.0, 0, 0, 0]), -q90, 0.5), _about_z(math.pi / 4).rotation)


def test_interpolated_correction_hand_computed() -> None:
    """Corrections identity at t=0 and (90 deg about z, +10 m x) at t=10: at t=2.5 the correction is 22.5 deg
    and +2.5 m, applied on the left of the WIGO pose."""
    a = TimedPose(0, Pose.identity())
    b = TimedPose(10, _about_z(math.pi / 2, (10.0, 0.0, 0.0)))
    _assert_pose(interpolate_pose(a, b, 5), _about_z(math.pi / 4, (5.0, 0.0, 0.0)))
    wigo = _about_z(0.3, (1.0, 2.0, 3.0))
    refined = corrected_pose(wigo, 2, [a, TimedPose(8, b.pose)])
    correction = _about_z(math.pi / 8, (2.5, 0.0, 0.0))
    assert refined.source == "wigo+sfm"
    _assert_pose(refined.global_from_ego, correction @ wigo)


def test_constant_correction_applied_exactly() -> None:
    """The same correction at both keyframes is applied unchanged, inside and (held) beyond them."""
    c = _about_z(0.7, (4.0, -1.0, 0.5))
    corrections = [TimedPose(100, c), TimedPose(200, c)]
    wigo = _about_z(-0.2, (10.0, 20.0, 1.0))
    for t in (150, 100, 250, 50):
        refined = corrected_pose(wigo, t, corrections, max_gap_us=1000)
        assert refined.source == "wigo+sfm"
        _assert_pose(refined.global_from_ego, c @ wigo)


def test_far_from_any_sfm_keyframe_is_plain_wigo() -> None:
    """No SfM keyframe within the gap on either side, or none at all: the WIGO pose, source `wigo`."""
    wigo = _about_z(0.1, (1.0, 1.0, 1.0))
    corrections = [TimedPose(0, _about_z(0.5))]
    for refined in (corrected_pose(wigo, 10_000, corrections, max_gap_us=100), corrected_pose(wigo, 5, [])):
        assert refined.source == "wigo"
        _assert_pose(refined.global_from_ego, wigo)
