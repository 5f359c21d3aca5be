"""Merging clips: the similarity between two clips is recovered from the 3D points their matches tie."""

import numpy as np
import pycolmap
import pytest
from scipy.spatial.transform import Rotation

from cama_pipeline.cameras import CameraView
from cama_pipeline.sfm.height_ties import tie_heights
from cama_pipeline.sfm.merge import (
    Alignment,
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


def _drive(scene: str, xs: np.ndarray, y: float, lift: float) -> ClipModel:
    """A clip of one view per ego position along y = const on a road rising 2 % in x, `lift` metres too high."""
    views = []
    for k, x in enumerate(xs):
        pose = np.eye(4)
        pose[:3, 3] = (float(x), y, 0.02 * float(x) + lift)
        name = f"{scene}-{k}"
        views.append(CameraView(name, name, scene, "CAM_FRONT", k, k, pose, np.eye(4), np.eye(3), 40, 30))
    return ClipModel(scene, pycolmap.Reconstruction(), tuple(views))


def _heights(clip: ClipModel, alignment: object) -> np.ndarray:
    similarity = alignment.world_from_clip  # type: ignore[attr-defined]
    return np.array([v.world_from_ego[:3, 3] for v in clip.views]) @ similarity[2, :3] + similarity[2, 3]


def test_free_heights_of_unjoined_clips_are_tied_to_the_road_the_others_drove() -> None:
    """Three clips no point joins: the measured one stays, the free one 2.6 m too high on the lane beside it is
    brought down onto its road, the free one far away keeps its height and is reported untied; with nothing
    free, nothing moves."""
    measured = _drive("a", np.arange(0.0, 60.0, 1.0), 0.0, 0.0)
    beside = _drive("b", np.arange(10.0, 50.0, 1.5), 3.5, 2.6)
    far = _drive("c", np.arange(500.0, 540.0, 1.0), 0.0, -1.0)
    clips = [measured, beside, far]
    alignments = [Alignment(c.scene, None, "poses", 0, np.eye(4)) for c in clips]
    tied, ties = tie_heights(clips, alignments, {"b", "c"}, radius_m=4.0, min_pairs=2)
    assert set(ties) == {"b", "c"} and ties["b"].tied and not ties["c"].tied
    assert ties["b"].offset_m == pytest.approx(-2.6, abs=1e-9) and ties["b"].pairs > len(beside.views)
    np.testing.assert_allclose(_heights(beside, tied[1]), 0.02 * np.arange(10.0, 50.0, 1.5), atol=1e-9)
    np.testing.assert_array_equal(tied[0].world_from_clip, np.eye(4))
    np.testing.assert_array_equal(tied[2].world_from_clip, np.eye(4))
    untouched, none = tie_heights(clips, alignments, set(), radius_m=4.0, min_pairs=2)
    assert none == {} and all(np.array_equal(a.world_from_clip, np.eye(4)) for a in untouched)


def test_with_every_height_free_the_largest_group_sets_it() -> None:
    """No clip measured: the clip with the most views keeps its height and the other is tied to it."""
    long = _drive("long", np.arange(0.0, 80.0, 1.0), 0.0, 1.0)
    short = _drive("short", np.arange(20.0, 40.0, 1.0), 0.0, -0.5)
    alignments = [Alignment(c.scene, None, "poses", 0, np.eye(4)) for c in (long, short)]
    tied, ties = tie_heights([long, short], alignments, {"long", "short"}, radius_m=4.0, min_pairs=2)
    assert set(ties) == {"short"} and ties["short"].offset_m == pytest.approx(1.5, abs=1e-9)
    np.testing.assert_array_equal(tied[0].world_from_clip, np.eye(4))


def test_merge_config_refuses_a_bad_height_tie() -> None:
    with pytest.raises(ValueError, match="height_tie_radius_m must be > 0"):
        MergeConfig(height_tie_radius_m=0.0)
    with pytest.raises(ValueError, match="height_tie_min_pairs must be >= 1"):
        MergeConfig(height_tie_min_pairs=0)
