"""Projection of 3D polylines into a pinhole camera: front-of-camera, image and range clipping."""

import numpy as np
import pytest

from cama_pipeline.evaluate.projection import PinholeCamera, ProjectionConfig, densify, project_polyline

K = np.array([[500.0, 0.0, 320.0], [0.0, 500.0, 240.0], [0.0, 0.0, 1.0]])


def camera_at_origin(width: int = 640, height: int = 480) -> PinholeCamera:
    """A camera at the global origin with global = camera axes."""
    return PinholeCamera(np.eye(3), np.zeros(3), K, width, height)


def test_densify_keeps_ends_and_limits_spacing() -> None:
    dense = densify(np.array([[0.0, 0.0, 0.0], [10.0, 0.0, 0.0]]), 0.5)
    assert len(dense) == 21
    assert np.allclose(dense[[0, -1]], [[0, 0, 0], [10, 0, 0]])
    assert np.linalg.norm(np.diff(dense, axis=0), axis=1).max() <= 0.5 + 1e-9


def test_points_behind_camera_are_dropped() -> None:
    line = np.array([[0.0, 1.0, -5.0], [0.0, 1.0, 10.0]])  # from behind to in front, 1 m below the camera
    pieces = project_polyline(line, camera_at_origin(), ProjectionConfig())
    assert len(pieces) == 1
    uv = pieces[0].points_px
    z = 500.0 / (uv[:, 1] - 240.0)  # depth of each projected point from v = f * y / z
    assert z.min() >= 0.5 - 1e-6
    assert np.allclose(uv[:, 0], 320.0)


def test_wholly_behind_camera_gives_nothing() -> None:
    line = np.array([[0.0, 1.0, -5.0], [0.0, 1.0, -1.0]])
    assert project_polyline(line, camera_at_origin(), ProjectionConfig()) == []


def test_clipped_exactly_at_image_border() -> None:
    line = np.array([[-20.0, 0.0, 10.0], [20.0, 0.0, 10.0]])  # spans far beyond both image sides
    (piece,) = project_polyline(line, camera_at_origin(), ProjectionConfig())
    assert piece.points_px[:, 0].min() == pytest.approx(-0.5)
    assert piece.points_px[:, 0].max() == pytest.approx(639.5)
    assert not piece.start_open and not piece.end_open


def test_range_crop_marks_open_end() -> None:
    line = np.array([[0.0, 1.5, 2.0], [0.0, 1.5, 100.0]])
    (piece,) = project_polyline(line, camera_at_origin(), ProjectionConfig(range_m=30.0))
    assert not piece.start_open and piece.end_open
    far_v = piece.points_px[:, 1].min()
    assert far_v == pytest.approx(240.0 + 500.0 * 1.5 / 30.0, abs=0.5)


def test_rotated_camera_matches_opencv() -> None:
    import cv2

    rvec = np.array([0.1, -0.2, 0.05])
    cam_from_global, _ = cv2.Rodrigues(rvec)
    tvec = np.array([0.3, -0.2, 1.0])
    camera = PinholeCamera(cam_from_global.T, -cam_from_global.T @ tvec, K, 640, 480)
    points = np.array([[0.5, 0.2, 8.0], [0.7, 0.3, 9.0]])
    (piece,) = project_polyline(points, camera, ProjectionConfig(spacing_m=10.0))
    expected, _ = cv2.projectPoints(points, rvec, tvec, K, None)
    assert np.allclose(piece.points_px[[0, -1]], expected[:, 0, :], atol=1e-6)


@pytest.mark.parametrize(
    "points, message",
    [
        (np.array([[0.0, 0.0, 1.0]]), "N >= 2"),
        (np.array([[0.0, 0.0, 1.0], [np.nan, 0.0, 2.0]]), "finite"),
        (np.array([[0.0, 0.0], [1.0, 0.0]]), r"\(N, 3\)"),
    ],
)
def test_bad_polylines_raise(points: np.ndarray, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        project_polyline(points, camera_at_origin(), ProjectionConfig())


def test_bad_config_and_camera_raise() -> None:
    with pytest.raises(ValueError, match="near_m"):
        ProjectionConfig(near_m=0.0)
    with pytest.raises(ValueError, match="range_m"):
        ProjectionConfig(range_m=-1.0)
    with pytest.raises(ValueError, match="image size"):
        PinholeCamera(np.eye(3), np.zeros(3), K, 0, 480)
