"""Ground-truth co-visibility: hand-made cameras on a flat surface, and the neighbour shortcut changes nothing."""

import numpy as np
import pytest

from cama_pipeline.evaluate.covisibility import (
    NEIGHBOUR_MARGIN_M,
    CameraStack,
    ElevationSurface,
    covisibility_matrix,
    ground_points,
    neighbours,
    seen_share,
)
from tests.pairs.pair_views import view

RANGE_M = 25.0
GRID = (12, 48)


@pytest.fixture()
def flat() -> ElevationSurface:
    """Flat ground at z = 0 over x, y in [-150, 150] m, 0.5 m cells."""
    return ElevationSurface(np.zeros((600, 600)), (-150.0, 150.0), 0.5)


def test_same_pose_sees_everything_opposite_or_far_sees_nothing(flat):
    views = [view(0, 0, 0), view(0, 0, 0, frame=1), view(0, 0, 180, frame=2), view(80, 0, 0, frame=3)]
    matrix = covisibility_matrix(views, flat, grid=GRID, max_range_m=RANGE_M)
    assert matrix.dtype == np.float32 and np.allclose(np.diag(matrix), 1.0)
    # ground samples are within the range on the ground, so the farthest are out of the 3D range of a camera
    # 1.5 m up: a camera sees a bit under all of its own footprint samples, and an identical one the same share
    own = seen_share(ground_points(views[0], flat, GRID, RANGE_M), CameraStack.of(views[:1]), RANGE_M)[0]
    assert 0.85 < own < 1.0
    assert matrix[0, 1] == pytest.approx(own) and matrix[1, 0] == pytest.approx(own)
    assert matrix[0, 2] == 0.0 and matrix[2, 0] == 0.0
    assert matrix[0, 3] == 0.0 and matrix[3, 0] == 0.0


def test_a_camera_further_ahead_sees_part_of_the_ground(flat):
    matrix = covisibility_matrix(
        [view(0, 0, 0), view(10, 0, 0, frame=1)], flat, grid=GRID, max_range_m=RANGE_M
    )
    assert 0.2 < matrix[0, 1] < 0.9
    assert (
        matrix[1, 0] > matrix[0, 1]
    )  # the leading camera's ground is ahead, which the trailing one also sees


def test_neighbours_are_the_cameras_within_twice_the_range():
    views = [
        view(0, 0, 0),
        view(2 * RANGE_M, 0, 0, frame=1),
        view(2 * RANGE_M + NEIGHBOUR_MARGIN_M + 1, 0, 0),
    ]
    near = neighbours(views, RANGE_M)
    assert list(near[0]) == [0, 1]
    assert list(near[2]) == [1, 2]
    assert neighbours([], RANGE_M) == []


def test_the_neighbour_shortcut_gives_the_all_pairs_matrix(flat):
    rng = np.random.default_rng(3)
    views = [
        view(x, y, yaw, frame=k, mount_yaw_deg=mount)
        for k, (x, y, yaw, mount) in enumerate(
            zip(
                rng.uniform(-100, 100, 40),
                rng.uniform(-20, 20, 40),
                rng.uniform(-180, 180, 40),
                rng.choice([0.0, 55.0, -55.0, 180.0], 40),
                strict=True,
            )
        )
    ]
    matrix = covisibility_matrix(views, flat, grid=GRID, max_range_m=RANGE_M)
    cameras = CameraStack.of(views)
    brute = np.stack([seen_share(ground_points(v, flat, GRID, RANGE_M), cameras, RANGE_M) for v in views])
    np.fill_diagonal(brute, 1.0)
    assert np.count_nonzero(brute) > len(views) * 2
    assert np.count_nonzero(brute == 0) > len(views) ** 2 // 2  # the shortcut has pairs to skip
    np.testing.assert_allclose(matrix, brute, atol=1e-6)


def test_no_views_no_matrix(flat):
    assert covisibility_matrix([], flat).shape == (0, 0)
