"""`cama_pipeline.evaluate.ego_frames`: a height offset, tilt or shift that the poses and the surface share cancels in
the key frames' ego frames (the global frame keeps it), an error of the surface itself does not, and only points in
MapTR's range where the truth has a height or class are scored."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from annotations.geometry import Box
from cama_pipeline.evaluate.ego_frames import ego_class_iou, ego_height_errors
from cama_pipeline.semantics import Semantic


def true_height(xy: np.ndarray) -> np.ndarray:
    """A rolling road south of y = 12 m; no road (NaN) north of it."""
    z = 0.02 * xy[:, 0] + 0.05 * np.sin(0.3 * xy[:, 1])
    return np.where(xy[:, 1] < 12.0, z, np.nan)


def pose(x: float, y: float, yaw_deg: float) -> np.ndarray:
    """world_from_ego standing on the true road at (x, y), heading `yaw_deg`."""
    matrix = np.eye(4)
    matrix[:3, :3] = Rotation.from_euler("z", yaw_deg, degrees=True).as_matrix()
    matrix[:3, 3] = [x, y, true_height(np.array([[x, y]]))[0]]
    return matrix


TRUE_POSES = {f"k{i}": pose(5.0 * i, 0.5 * i, 3.0 * i) for i in range(6)}
GRID = np.stack(np.meshgrid(np.arange(-20.0, 60.0, 0.5), np.arange(-20.0, 20.0, 0.5)), axis=-1).reshape(-1, 2)
ROAD = GRID[np.isfinite(true_height(GRID))]
TRUE_POINTS = np.column_stack([ROAD, true_height(ROAD)])


def moved(points: np.ndarray, transform: np.ndarray) -> np.ndarray:
    return points @ transform[:3, :3].T + transform[:3, 3]


def shared_error() -> np.ndarray:
    """A placement error of the whole site: 3 cm too high, tilted 0.1 deg, shifted 8 cm east and turned 0.2 deg."""
    transform = np.eye(4)
    transform[:3, :3] = Rotation.from_euler("xz", [0.1, 0.2], degrees=True).as_matrix()
    transform[:3, 3] = [0.08, 0.0, 0.03]
    return transform


def test_the_true_surface_under_the_true_poses_has_no_error() -> None:
    errors = ego_height_errors(TRUE_POINTS, TRUE_POSES, TRUE_POSES, true_height)
    assert errors.keyframes == 6 and len(errors.error_m) > 1000
    assert np.abs(errors.error_m).max() < 1e-9
    assert np.abs(errors.world_error_m).max() < 1e-9


def test_an_offset_and_tilt_the_poses_and_surface_share_cancel_in_the_ego_frames() -> None:
    site = shared_error()
    poses = {key: site @ matrix for key, matrix in TRUE_POSES.items()}
    errors = ego_height_errors(moved(TRUE_POINTS, site), poses, TRUE_POSES, true_height)
    summary = errors.summary()
    # the residual is the rolling road read a few centimetres off where the shared shift moved it, not the offset
    assert summary["rmse_cm"] < 0.2
    assert summary["same_pairs_in_global_frame"]["rmse_cm"] > 2.0
    assert 2.5 < summary["same_pairs_in_global_frame"]["median_signed_cm"] < 3.5


def test_an_error_of_the_surface_itself_stays_in_the_ego_frames() -> None:
    raised = TRUE_POINTS + np.array([0.0, 0.0, 0.02])
    errors = ego_height_errors(raised, TRUE_POSES, TRUE_POSES, true_height)
    assert np.allclose(errors.error_m, 0.02, atol=1e-9)
    summary = errors.summary()
    assert summary["rmse_cm"] == pytest.approx(2.0) and summary["median_signed_cm"] == pytest.approx(2.0)
    assert all(
        band["rmse_cm"] is None or band["rmse_cm"] == pytest.approx(2.0)
        for band in summary["by_distance_m"].values()
    )


def test_only_points_in_range_with_a_true_height_are_scored() -> None:
    box = Box(xmin=-10.0, xmax=10.0, ymin=-5.0, ymax=5.0)
    one = {"k0": TRUE_POSES["k0"]}
    errors = ego_height_errors(TRUE_POINTS, one, one, true_height, box)
    inside = (np.abs(TRUE_POINTS[:, 0]) <= 10.0) & (np.abs(TRUE_POINTS[:, 1]) <= 5.0)
    assert len(errors.error_m) == inside.sum()
    assert errors.distance_m.max() <= np.hypot(10.0, 5.0)
    # a point the truth has no height for (north of the road) is never scored
    off_road = np.array([[0.0, 15.0, 0.0]])
    assert len(ego_height_errors(off_road, one, one, true_height).error_m) == 0


def test_key_frames_are_paired_by_key_and_bad_arguments_are_named() -> None:
    ours = {"k1": TRUE_POSES["k1"], "other": TRUE_POSES["k2"]}
    assert ego_height_errors(TRUE_POINTS, ours, TRUE_POSES, true_height).keyframes == 1
    with pytest.raises(ValueError, match="points_xyz: expected"):
        ego_height_errors(TRUE_POINTS[:, :2], TRUE_POSES, TRUE_POSES, true_height)
    with pytest.raises(ValueError, match="no key frame is posed by both"):
        ego_height_errors(TRUE_POINTS, {"x": TRUE_POSES["k0"]}, TRUE_POSES, true_height)


def true_label(xy: np.ndarray) -> np.ndarray:
    """A 0.2 m lane line along y = 3.025 m (no sample on its edge) on the road; unobserved west of x = -5 m."""
    labels = np.where(np.abs(xy[:, 1] - 3.025) < 0.1, int(Semantic.LANE_MARKING), int(Semantic.ROAD))
    return np.where(xy[:, 0] < -5.0, int(Semantic.UNOBSERVED), labels).astype(np.uint8)


FINE = np.stack(np.meshgrid(np.arange(-20.0, 60.0, 0.05), np.arange(0.0, 6.0, 0.05)), axis=-1).reshape(-1, 2)
CLASSES = {"road": int(Semantic.ROAD), "lane_marking": int(Semantic.LANE_MARKING)}


def test_labels_placed_by_a_shifted_frame_score_in_the_ego_frames_of_poses_shifted_alike() -> None:
    """Labels drawn 8 cm off with poses 8 cm off, as a site placed by a shifted gauge is, score fully in the ego
    frames; scored against the truth at their global place, the line's IoU falls."""
    site = shared_error()
    labels = true_label(FINE)
    moved_points = moved(np.column_stack([FINE, np.zeros(len(FINE))]), site)
    poses = {key: site @ matrix for key, matrix in TRUE_POSES.items()}
    iou = ego_class_iou(moved_points, labels, poses, TRUE_POSES, true_label, CLASSES)
    assert iou["ego"] == {"road": 1.0, "lane_marking": 1.0}
    assert iou["same_pairs_in_global_frame"]["lane_marking"] < 0.8
    unshared = ego_class_iou(moved_points, labels, TRUE_POSES, TRUE_POSES, true_label, CLASSES)
    assert unshared["ego"] == unshared["same_pairs_in_global_frame"]


def test_unobserved_truth_is_not_scored_and_a_class_nobody_holds_has_no_iou() -> None:
    labels = np.full(len(FINE), int(Semantic.ROAD), np.uint8)
    points = np.column_stack([FINE, np.zeros(len(FINE))])
    west = FINE[:, 0] < -5.0
    labels[west] = int(Semantic.CROSSWALK)  # wrong, but where the truth is unobserved
    classes = {**CLASSES, "crosswalk": int(Semantic.CROSSWALK)}
    iou = ego_class_iou(points, labels, TRUE_POSES, TRUE_POSES, true_label, classes)["ego"]
    assert iou["crosswalk"] is None and iou["lane_marking"] == 0.0
    with pytest.raises(ValueError, match="labels: expected one per point"):
        ego_class_iou(points, labels[:-1], TRUE_POSES, TRUE_POSES, true_label, classes)
