"""Transforms between site, global, ego and BEV-pixel coordinates: round trips and known cases."""

import numpy as np
import pytest

from annotations import (
    Georeference,
    ego_from_global_points,
    global_from_ego_points,
    global_from_pixel_points,
    global_from_site_points,
    pixel_from_global_points,
    pixel_from_site_points,
    rotation_from_quaternion,
    site_from_global_points,
    site_from_pixel_points,
)

RNG = np.random.default_rng(7)


def test_site_global_offset_and_round_trip() -> None:
    site = RNG.uniform(-50, 50, size=(20, 3))
    world = global_from_site_points(site, (412.0, 1085.0))
    np.testing.assert_allclose(world[:, :2] - site[:, :2], np.tile([412.0, 1085.0], (20, 1)))
    np.testing.assert_array_equal(world[:, 2], site[:, 2])
    np.testing.assert_allclose(site_from_global_points(world, (412.0, 1085.0)), site)
    with pytest.raises(ValueError, match="site_origin_xy"):
        global_from_site_points(site, (1.0, 2.0, 3.0))


def test_a_point_ahead_of_an_ego_yawed_90_degrees() -> None:
    rotation = rotation_from_quaternion([np.cos(np.pi / 4), 0.0, 0.0, np.sin(np.pi / 4)])
    np.testing.assert_allclose(rotation, [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-12)
    translation = np.array([100.0, 200.0, 5.0])
    ahead_global = global_from_ego_points([[10.0, 0.0, 0.0], [0.0, 2.0, 0.0]], rotation, translation)
    np.testing.assert_allclose(ahead_global, [[100.0, 210.0, 5.0], [98.0, 200.0, 5.0]], atol=1e-12)
    np.testing.assert_allclose(
        ego_from_global_points([[100.0, 210.0, 5.0]], rotation, translation), [[10.0, 0.0, 0.0]], atol=1e-12
    )


def test_ego_global_round_trip_with_random_poses() -> None:
    for _ in range(5):
        rotation = rotation_from_quaternion(RNG.normal(size=4))
        translation = RNG.uniform(-500, 500, size=3)
        points = RNG.uniform(-30, 30, size=(50, 3))
        back = ego_from_global_points(
            global_from_ego_points(points, rotation, translation), rotation, translation
        )
        np.testing.assert_allclose(back, points, atol=1e-9)


def test_bad_poses_and_points_are_rejected() -> None:
    with pytest.raises(ValueError, match="rotation: not a proper rotation"):
        ego_from_global_points([[0.0, 0.0, 0.0]], np.diag([1.0, 1.0, -1.0]), [0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="translation"):
        ego_from_global_points([[0.0, 0.0, 0.0]], np.eye(3), [0.0, 0.0])
    with pytest.raises(ValueError, match=r"points: expected an array of shape \(N, 3\)"):
        ego_from_global_points([[0.0, 0.0]], np.eye(3), [0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="quaternion_wxyz"):
        rotation_from_quaternion([0.0, 0.0, 0.0, 0.0])


def test_pixel_convention(georef: Georeference) -> None:
    x0, y0 = georef.origin_xy
    np.testing.assert_allclose(pixel_from_global_points([[x0, y0]], georef), [[0.0, 0.0]])
    np.testing.assert_allclose(pixel_from_global_points([[x0 + 1.0, y0 - 1.5, 9.0]], georef), [[2.0, 3.0]])
    np.testing.assert_allclose(global_from_pixel_points([[2.0, 3.0]], georef), [[x0 + 1.0, y0 - 1.5]])
    np.testing.assert_allclose(pixel_from_site_points([[0.0, 20.0], [19.5, 0.5]], georef), [[0, 0], [39, 39]])


def test_pixel_round_trips(georef: Georeference) -> None:
    site = RNG.uniform(0, 20, size=(30, 2))
    np.testing.assert_allclose(site_from_pixel_points(pixel_from_site_points(site, georef), georef), site)
    pixels = RNG.uniform(0, 40, size=(30, 2))
    np.testing.assert_allclose(
        pixel_from_global_points(global_from_pixel_points(pixels, georef), georef), pixels
    )
    with pytest.raises(ValueError, match="pixels"):
        global_from_pixel_points([[1.0, 2.0, 3.0]], georef)
