"""Pose and elevation error helpers on known offsets."""

import math

import numpy as np
import pytest

from cama_pipeline.data import Pose
from cama_pipeline.evaluate.errors import elevation_errors, pose_errors, umeyama_alignment


def yaw_pose(x: float, y: float, yaw_deg: float) -> Pose:
    """A pose at (x, y, 0) rotated by yaw about z."""
    half = math.radians(yaw_deg) / 2
    return Pose(np.array([x, y, 0.0]), np.array([math.cos(half), 0.0, 0.0, math.sin(half)]))


TRUE = [yaw_pose(float(i), 0.5 * i, 10.0 * i) for i in range(6)]


def test_translation_offset() -> None:
    estimated = [Pose(p.translation + [0.3, 0.4, 0.0], p.rotation) for p in TRUE]
    errors = pose_errors(estimated, TRUE)
    assert errors.position_rmse_m == pytest.approx(0.5)
    assert errors.rotation_rmse_deg == pytest.approx(0.0, abs=1e-6)
    assert errors.ate_m == pytest.approx(0.5)
    assert pose_errors(estimated, TRUE, alignment="se3").ate_m == pytest.approx(0.0, abs=1e-9)


def test_heading_offset_wraps() -> None:
    estimated = [yaw_pose(*p.translation[:2], 10.0 * i + 2.0) for i, p in enumerate(TRUE)]
    errors = pose_errors(estimated, TRUE)
    assert errors.heading_rmse_deg == pytest.approx(2.0)
    assert errors.rotation_rmse_deg == pytest.approx(2.0)
    wrapped = pose_errors([yaw_pose(0, 0, 179.0)], [yaw_pose(0, 0, -179.0)])
    assert wrapped.heading_rmse_deg == pytest.approx(2.0)


def test_sim3_alignment_recovers_scale() -> None:
    rng = np.random.default_rng(0)
    source = rng.normal(size=(20, 3))
    rotation = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    target = 2.0 * source @ rotation.T + [1.0, 2.0, 3.0]
    r, t, s = umeyama_alignment(source, target, with_scale=True)
    assert s == pytest.approx(2.0) and np.allclose(r, rotation) and np.allclose(t, [1, 2, 3])


def test_elevation_errors_over_mask() -> None:
    true = np.zeros((4, 4))
    estimated = np.full((4, 4), 0.2)
    estimated[0, 0] = np.nan
    mask = np.ones((4, 4), bool)
    mask[3] = False
    errors = elevation_errors(estimated, true, mask)
    assert errors.count == 11
    assert (
        errors.rmse_m == pytest.approx(0.2)
        and errors.mae_m == pytest.approx(0.2)
        and errors.bias_m == pytest.approx(0.2)
    )


def test_bad_inputs_raise() -> None:
    with pytest.raises(ValueError, match="equally long"):
        pose_errors(TRUE[:2], TRUE)
    with pytest.raises(ValueError, match="alignment"):
        pose_errors(TRUE, TRUE, alignment="affine")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="same shape"):
        elevation_errors(np.zeros((2, 2)), np.zeros((3, 3)))
    with pytest.raises(ValueError, match="no cell"):
        elevation_errors(np.zeros((2, 2)), np.zeros((2, 2)), np.zeros((2, 2), bool))
