"""Merging clips: the similarity between two clips is recovered from the 3D points their matches tie."""

import numpy as np
import pycolmap
import pytest
from scipy.spatial.transform import Rotation

from cama_pipeline.cameras import CameraView
from cama_pipeline.sfm.merge import (
    ClipModel,
    MergeConfig,
    align_clips,
    aligned_views,
    estimate_similarity,
    merge_groups,
)

RNG = np.random.default_rng(7)


def similarity(
    scale: float,
    yaw_deg: float,
    shift: tuple[float, float, float],
    about: tuple[float, float, float] = (0, 0, 0),
) -> np.ndarray:
    """4x4 [sR | t]: scaled rotation about z around the point `about`, then moved by `shift`."""
    c, s = np.cos(np.radians(yaw_deg)), np.sin(np.radians(yaw_deg))
    out = np.eye(4)
    out[:3, :3] = scale * np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    out[:3, 3] = np.asarray(about) + np.asarray(shift) - out[:3, :3] @ np.asarray(about)
    return out


def apply(transform: np.ndarray, points: np.ndarray) -> np.ndarray:
    return points @ transform[:3, :3].T + transform[:3, 3]


def view(name: str, scene: str, centre: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> CameraView:
    pose = np.eye(4)
    pose[:3, 3] = centre
    return CameraView(name, name, scene, "CAM_FRONT", 0, 0, pose, np.eye(4), np.eye(3), 40, 30)


def clip(scene: str, name: str, xyz: np.ndarray) -> ClipModel:
    """A one-image model observing `xyz` (keypoint k sees point k)."""
    model = pycolmap.Reconstruction()
    model.add_camera_with_trivial_rig(
        pycolmap.Camera(camera_id=1, model="PINHOLE", width=40, height=30, params=[20, 20, 20, 15])
    )
    points = [pycolmap.Point2D(np.array([1.0, 1.0])) for _ in xyz]
    model.add_image_with_trivial_frame(
        pycolmap.Image(name=name, camera_id=1, image_id=1, points2D=points), pycolmap.Rigid3d()
    )
    for k, point in enumerate(xyz):
        track = pycolmap.Track()
        track.add_element(1, k)
        model.add_point3D(point, track)
    return ClipModel(scene, model, (view(name, scene, tuple(xyz.mean(axis=0) - [0.0, 0.0, 5.0])),))


def test_similarity_recovered_despite_outliers() -> None:
    world = RNG.uniform(-30, 30, size=(200, 3)) + [500.0, 1000.0, 0.0]
    truth = similarity(1.01, 2.0, (0.4, -0.3, 0.1), about=(500.0, 1000.0, 0.0))
    source = apply(np.linalg.inv(truth), world)
    source[:30] += RNG.normal(scale=5.0, size=(30, 3))  # wrong matches
    estimate = estimate_similarity(source, world, MergeConfig())
    assert estimate is not None
    found, inliers = estimate
    assert 165 <= inliers <= 175
    np.testing.assert_allclose(found, truth, atol=1e-6)


def test_implausible_or_unsupported_similarity_is_refused() -> None:
    world = RNG.uniform(-30, 30, size=(100, 3))
    assert estimate_similarity(world[:10], world[:10], MergeConfig()) is None  # too few points
    far = apply(similarity(1.0, 30.0, (0, 0, 0)), world)
    assert estimate_similarity(world, far, MergeConfig()) is None  # 30 deg: not a correction of odometry


def test_two_clips_sharing_points_are_aligned_and_grouped() -> None:
    world = RNG.uniform(-20, 20, size=(60, 3)) + [300.0, 200.0, 5.0]
    truth = similarity(
        0.99, -1.5, (0.8, 0.2, -0.1), about=(300.0, 200.0, 5.0)
    )  # second clip's world_from_clip
    first = clip("scene-a", "a.jpg", np.concatenate([world, RNG.uniform(-20, 20, (20, 3))]))
    second = clip("scene-b", "b.jpg", apply(np.linalg.inv(truth), world))
    lonely = clip("scene-c", "c.jpg", RNG.uniform(-20, 20, size=(50, 3)))
    matches = [("b.jpg", "a.jpg", np.stack([np.arange(60), np.arange(60)], axis=1))]
    alignments = align_clips([second, first, lonely], matches, MergeConfig())
    by_scene = {a.scene: a for a in alignments}
    (moved,) = [a for a in alignments if a.method == "points"]
    assert {moved.scene, moved.reference} == {"scene-a", "scene-b"}
    reference = by_scene[moved.reference]  # type: ignore[index]
    assert reference.method == "poses"
    relative = np.linalg.inv(reference.world_from_clip) @ moved.world_from_clip
    expected = truth if moved.scene == "scene-b" else np.linalg.inv(truth)
    np.testing.assert_allclose(relative, expected, atol=1e-6)
    assert moved.correspondences == 60
    clips = {"scene-a": first, "scene-b": second}
    own = np.array([clips[a.scene].views[0].center for a in (moved, reference)])
    placed = np.array([apply(a.world_from_clip, own[i][None])[0] for i, a in enumerate((moved, reference))])
    np.testing.assert_allclose(placed.mean(axis=0), own.mean(axis=0), atol=1e-6)  # the pair is re-centred
    rotvecs = [
        Rotation.from_matrix(a.world_from_clip[:3, :3] / a.scale).as_rotvec() for a in (moved, reference)
    ]
    np.testing.assert_allclose(np.mean(rotvecs, axis=0), 0.0, atol=1e-9)  # and keeps the clips' mean rotation
    assert by_scene["scene-c"].method == "poses" and np.allclose(
        by_scene["scene-c"].world_from_clip, np.eye(4)
    )
    groups = sorted(sorted(g) for g in merge_groups(alignments))
    assert groups == [["scene-a", "scene-b"], ["scene-c"]]


def test_aligned_views_move_the_ego_poses_rigidly() -> None:
    transform = similarity(1.02, 10.0, (1.0, 2.0, 3.0))
    (moved,) = aligned_views([view("a.jpg", "s", (5.0, 0.0, 0.0))], transform)
    np.testing.assert_allclose(moved.world_from_ego[:3, 3], apply(transform, np.array([[5.0, 0, 0]]))[0])
    rotation = moved.world_from_ego[:3, :3]
    np.testing.assert_allclose(rotation @ rotation.T, np.eye(3), atol=1e-12)
    assert np.degrees(np.arctan2(rotation[1, 0], rotation[0, 0])) == pytest.approx(10.0)
