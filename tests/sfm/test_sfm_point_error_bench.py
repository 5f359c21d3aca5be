"""`bench/sfm_point_error.py` splits the SfM road points' height error by what the model knows of each point: the
widest angle between its rays, its nearest camera, and bins of those."""

import numpy as np
import pycolmap
import pytest

from bench.sfm_point_error import FAR_M, binned, model_geometry, ray_geometry, summary


def two_camera_model(points: list[tuple[float, float, float]]) -> pycolmap.Reconstruction:
    """Cameras at x = 0 and x = 1 m (looking along z), each observing every point."""
    model = pycolmap.Reconstruction()
    model.add_camera_with_trivial_rig(
        pycolmap.Camera(camera_id=1, model="PINHOLE", width=40, height=30, params=[20, 20, 20, 15])
    )
    for image_id, centre_x in ((1, 0.0), (2, 1.0)):
        image = pycolmap.Image(
            name=f"cam{image_id}.jpg",
            camera_id=1,
            image_id=image_id,
            points2D=[pycolmap.Point2D(np.array([1.0, 1.0])) for _ in points],
        )
        cam_from_world = pycolmap.Rigid3d(pycolmap.Rotation3d(), np.array([-centre_x, 0.0, 0.0]))
        model.add_image_with_trivial_frame(image, cam_from_world)
    for k, point in enumerate(points):
        track = pycolmap.Track()
        track.add_element(1, k)
        track.add_element(2, k)
        model.add_point3D(np.array(point), track)
    return model


def test_the_rays_angle_and_the_nearest_camera() -> None:
    angle, near = ray_geometry(np.array([0.5, 0.0, 10.0]), np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]]))
    assert angle == pytest.approx(np.degrees(2 * np.arctan(0.5 / 10)))
    assert near == pytest.approx(np.hypot(0.5, 10))
    angle, near = ray_geometry(np.array([0.0, 0.0, 2.0]), np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]]))
    assert angle == pytest.approx(np.degrees(np.arctan(0.5)))
    assert near == pytest.approx(2.0)


def test_model_geometry_follows_each_point_whatever_the_order_it_is_asked_in() -> None:
    model = two_camera_model([(0.5, 0.0, 10.0), (0.5, 0.0, 2.0)])
    found = model_geometry(model, np.array([[0.5, 0.0, 2.0], [0.5, 0.0, 10.0]]))
    np.testing.assert_allclose(
        found["triangulation_deg"], np.degrees(2 * np.arctan(0.5 / np.array([2.0, 10.0])))
    )
    np.testing.assert_allclose(found["range_m"], np.hypot(0.5, [2.0, 10.0]))
    np.testing.assert_array_equal(found["track_length"], [2, 2])
    with pytest.raises(ValueError, match="not the model's"):
        model_geometry(model, np.array([[0.5, 0.0, 3.0]]))


def test_bins_hold_their_points_and_say_how_far_off_they_are() -> None:
    values = np.array([0.5, 1.5, 1.6, 5.0])
    errors = np.array([0.01, -0.2, 0.3, 0.02])
    rows = binned(values, errors, (0, 1, 2, 3, 10))
    assert [(row["from"], row["to"], row["points"]) for row in rows] == [(0, 1, 1), (1, 2, 2), (3, 10, 1)]
    assert rows[1]["share"] == 0.5
    assert rows[1]["median_cm"] == pytest.approx(25.0)
    assert rows[1]["beyond_10cm"] == 1.0
    assert rows[0]["beyond_10cm"] == 0.0
    whole = summary(errors, len(errors))
    assert whole["points"] == 4 and whole["share"] == 1.0
    assert whole["beyond_10cm"] == pytest.approx(np.mean(np.abs(errors) > FAR_M))
