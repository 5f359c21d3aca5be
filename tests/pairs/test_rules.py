"""Each HSP rule on hand-made camera configurations."""

import numpy as np
import pytest

from cama_pipeline.pairs.config import PairsConfig
from cama_pipeline.pairs.footprint import footprint_overlap, ground_footprint
from cama_pipeline.pairs.rules import face_to_face, height_compatible, view_cones_overlap
from tests.pairs.pair_views import view

CONFIG = PairsConfig()


def test_height_rule_separates_road_levels() -> None:
    assert height_compatible(np.array([0, 0, 1.5]), np.array([5, 0, 3.5]), max_dz_m=3.0)
    assert not height_compatible(np.array([0, 0, 1.5]), np.array([5, 0, 6.0]), max_dz_m=3.0)


def test_view_cone_rule_drops_cameras_looking_away_from_each_other() -> None:
    a, b = np.array([0.0, 0, 0]), np.array([-5.0, 0, 0])
    forward, backward = np.array([1.0, 0, 0]), np.array([-1.0, 0, 0])
    assert not view_cones_overlap(a, forward, b, backward)  # back to back: theta1 180, b behind a
    assert view_cones_overlap(a, forward, b, forward)  # same direction, b behind a: a's view is b's
    assert view_cones_overlap(a, forward, np.array([5.0, 0, 0]), backward)  # facing each other
    assert view_cones_overlap(a, forward, b, np.array([0.0, 1, 0]))  # 90 degrees is not over 90


def test_face_to_face_rule_needs_opposed_axes_close_together_each_in_front() -> None:
    a, forward, backward = np.array([0.0, 0, 0]), np.array([1.0, 0, 0]), np.array([-1.0, 0, 0])
    rule = {"min_angle_deg": 150.0, "max_distance_m": 12.0}
    assert face_to_face(a, forward, np.array([8.0, 0, 0]), backward, **rule)
    assert not face_to_face(a, forward, np.array([20.0, 0, 0]), backward, **rule)  # far apart
    assert not face_to_face(a, forward, np.array([-8.0, 0, 0]), backward, **rule)  # back to back
    assert not face_to_face(a, forward, np.array([8.0, 0, 0]), np.array([0.0, -1, 0]), **rule)


def test_ground_footprint_lies_ahead_within_range() -> None:
    front = ground_footprint(view(0, 0, 0), CONFIG.footprint_grid, CONFIG.footprint_max_range_m)
    assert front.area > 50
    xmin, ymin, xmax, ymax = front.bounds
    assert xmin > 0 and xmax <= 1.0 + CONFIG.footprint_max_range_m + 1e-6  # ahead of the car, within range
    rear = ground_footprint(
        view(0, 0, 0, channel="CAM_BACK", mount_yaw_deg=180),
        CONFIG.footprint_grid,
        CONFIG.footprint_max_range_m,
    )
    assert rear.bounds[2] < 1.0  # behind the camera
    assert footprint_overlap(front, rear) == 0.0


def test_footprint_overlap_falls_with_distance_and_is_mutual() -> None:
    def footprint(x: float, yaw: float = 0.0) -> object:
        return ground_footprint(view(x, 0, yaw), CONFIG.footprint_grid, CONFIG.footprint_max_range_m)

    same = footprint_overlap(footprint(0), footprint(0))
    near = footprint_overlap(footprint(0), footprint(5))
    far = footprint_overlap(footprint(0), footprint(60))
    assert same == pytest.approx(1.0) and 0.3 < near < 1.0 and far == 0.0
    assert footprint_overlap(footprint(0), footprint(5)) == pytest.approx(
        footprint_overlap(footprint(5), footprint(0))
    )


def test_config_rejects_bad_values() -> None:
    with pytest.raises(ValueError, match="max_dz_m"):
        PairsConfig(max_dz_m=0)
    with pytest.raises(ValueError, match="min_footprint_overlap"):
        PairsConfig(min_footprint_overlap=1.5)
    with pytest.raises(ValueError, match="knn"):
        PairsConfig(knn=-1)
