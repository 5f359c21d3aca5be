"""Merging independently reconstructed clips: similarity alignment of each clip to its neighbours through the
3D points their cross-clip matches tie together, then one global re-triangulation and BA of the union,
which starts from the clips' points (`MergeConfig.seed_from_clips`).

Every clip starts in the global odometry frame (odometry-guided initialisation), so a clip without enough
shared points keeps its own poses ("poses" alignment, identity); clips linked by shared points are aligned
in order of overlap to the clip with the most registered images (Prim's order over the overlap graph).
"""

import logging
from collections.abc import Sequence
from dataclasses import dataclass, replace
from functools import cached_property
from pathlib import Path
from typing import Any, Literal

import numpy as np
import pycolmap
from scipy.spatial.transform import Rotation

from cama_pipeline.cameras import CameraView
from cama_pipeline.site.heights import TIE_MIN_PAIRS, TIE_RADIUS_M

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class MergeConfig:
    """When two clips count as overlapping and which similarity between them is believed."""

    min_correspondences: int = 20
    """Shared 3D points (tied by cross-clip matches) needed to align one clip to another."""
    max_error_m: float = 0.25
    """RANSAC inlier threshold of the similarity, metres."""
    max_shift_m: float = 5.0
    """A similarity moving the clip's centre further than this is rejected (odometry is better than that)."""
    max_rotation_deg: float = 5.0
    """A similarity rotating the clip more than this is rejected."""
    max_scale_change: float = 0.05
    """A similarity whose scale differs from 1 by more than this is rejected (poses have metric scale)."""
    global_max_iterations: int = 1
    """Iterative BA passes of the merged model at most: its clips were refined and cleaned already, so it
    needs the re-triangulation across clips and a global adjustment, not the whole Algorithm 1 again."""
    global_function_tolerance: float = 1e-6
    """BA of the merged model stops once an iteration lowers the cost by less than this fraction: it starts
    from refined clips, so the long tail of tiny steps a cold BA needs moves nothing that matters. Default
    site, clips scene-0002 + scene-0003 (438 images, 218k observations): one pass at 1e-6 takes 49 CPU s
    against 146 for two passes to full tolerance (56 solver steps instead of 2 x 101), same errors
    (gauge-free 1.05 cm / 0.036 deg)."""

    seed_from_clips: bool = True
    """Start the merged model from the clips' refined points (moved by their alignments; tracks then
    completed and merged across clips through the matches) instead of triangulating every match again.
    Default site (912 images, 3 clips), same clips, with `num_threads=2`: merge 82 s wall / 75 CPU s
    against 642 s / 343 CPU s for a fresh triangulation on one thread (on a loaded machine: 440 s wall
    triangulating, 190 s wall in its BA over 448k observations); errors 6.25 cm / 0.080 deg (gauge-free 0.57 cm / 0.021 deg) against
    6.35 cm / 0.079 deg (0.59 cm / 0.021 deg)."""
    num_threads: int = 2
    """Solver threads of the merged BA: it runs alone once the clips are done (COLMAP uses one thread
    below 50k residuals whatever this says)."""
    height_ties: bool = True
    """Give the clips that no point joins and whose heights nothing measured (2D logged poses, no GNSS) the
    height of the road the other clips drove (`cama_pipeline.sfm.height_ties`)."""
    height_ties_before_alignment: bool = True
    """Tie each free-height clip's height before the point alignment too, so that a clip WIGO left metres from
    the others is judged by `max_shift_m` from the road's height (`height_ties.heights_before_alignment`);
    off: only the tie after it (an ablation)."""
    height_tie_radius_m: float = TIE_RADIUS_M
    """A keyframe this close (horizontally) to another clip's track is taken to stand on the same road."""
    height_tie_min_pairs: int = TIE_MIN_PAIRS
    """Keyframes near the other group's track needed to tie a clip's height."""

    def __post_init__(self) -> None:
        if self.num_threads < 1:
            raise ValueError(f"MergeConfig.num_threads must be >= 1, got {self.num_threads}")
        if self.global_max_iterations < 1:
            raise ValueError(
                f"MergeConfig.global_max_iterations must be >= 1, got {self.global_max_iterations}"
            )
        if self.height_tie_min_pairs < 1:
            raise ValueError(
                f"MergeConfig.height_tie_min_pairs must be >= 1, got {self.height_tie_min_pairs}"
            )
        if self.min_correspondences < 3:
            raise ValueError(f"MergeConfig.min_correspondences must be >= 3, got {self.min_correspondences}")
        if not 0 <= self.global_function_tolerance < 1:
            raise ValueError(
                f"MergeConfig.global_function_tolerance must be in [0, 1), got {self.global_function_tolerance}"
            )
        for name in (
            "max_error_m",
            "max_shift_m",
            "max_rotation_deg",
            "max_scale_change",
            "height_tie_radius_m",
        ):
            if not getattr(self, name) > 0:
                raise ValueError(f"MergeConfig.{name} must be > 0, got {getattr(self, name)}")


@dataclass(frozen=True, eq=False)
class ClipModel:
    """One clip's reconstruction and its refined views (global frame)."""

    scene: str
    reconstruction: pycolmap.Reconstruction
    views: tuple[CameraView, ...]

    @cached_property
    def point_ids(self) -> dict[str, np.ndarray]:
        """Point3D id per keypoint of each registered image by name (built once: every pair reads it)."""
        return point_id_table(self.reconstruction)


@dataclass(frozen=True, eq=False)
class Alignment:
    """How one clip was brought into the merged frame: `world_from_clip` is a 4x4 similarity [sR | t]."""

    scene: str
    reference: str | None
    method: Literal["points", "poses"]
    correspondences: int
    world_from_clip: np.ndarray
    shift_m: float = 0.0
    """How far the alignment moved the centre of the clip's shared points (from where its prior put them)."""

    @property
    def scale(self) -> float:
        return float(np.cbrt(np.linalg.det(self.world_from_clip[:3, :3])))

    def to_json(self) -> dict[str, Any]:
        rotation = self.world_from_clip[:3, :3] / self.scale
        angle = np.degrees(np.arccos(np.clip((np.trace(rotation) - 1) / 2, -1.0, 1.0)))
        return {
            "reference": self.reference,
            "method": self.method,
            "correspondences": self.correspondences,
            "scale": self.scale,
            "rotation_deg": float(angle),
            "shift_m": self.shift_m,
        }


Correspondences = tuple[np.ndarray, np.ndarray]
"""(M, 3) points of clip A and the (M, 3) points of clip B they are matched to, clip-local coordinates."""


def cross_clip_matches(database_path: Path) -> list[tuple[str, str, np.ndarray]]:
    """(nameA, nameB, (M, 2) keypoint index pairs) of every verified pair in the database."""
    database = pycolmap.Database.open(str(database_path))
    try:
        names = {image.image_id: image.name for image in database.read_all_images()}
        pair_ids, geometries = database.read_two_view_geometries()
    finally:
        database.close()
    found = []
    for pair_id, geometry in zip(pair_ids, geometries, strict=True):
        first, second = pycolmap.pair_id_to_image_pair(pair_id)
        inliers = np.asarray(geometry.inlier_matches)
        if len(inliers):
            found.append((names[first], names[second], inliers))
    return found


def point_id_table(reconstruction: pycolmap.Reconstruction) -> dict[str, np.ndarray]:
    """Point3D id per keypoint (-1 where none) of every registered image, by image name."""
    table = {}
    for image in reconstruction.images.values():
        if image.has_pose:
            table[image.name] = np.array(
                [p.point3D_id if p.has_point3D() else -1 for p in image.points2D], dtype=np.int64
            )
    return table


def clip_correspondences(
    first: ClipModel, second: ClipModel, matches: Sequence[tuple[str, str, np.ndarray]]
) -> Correspondences:
    """3D points of `first` and `second` tied by matches between an image of each (unique point pairs)."""
    scene_images = {m.scene: {v.name for v in m.views} for m in (first, second)}
    tied: set[tuple[int, int]] = set()
    for name_a, name_b, inliers in matches:
        if name_a in scene_images[second.scene] and name_b in scene_images[first.scene]:
            name_a, name_b, inliers = name_b, name_a, inliers[:, ::-1]
        if name_a not in scene_images[first.scene] or name_b not in scene_images[second.scene]:
            continue
        ids_a, ids_b = first.point_ids.get(name_a), second.point_ids.get(name_b)
        if ids_a is None or ids_b is None:
            continue
        pa = ids_a[np.minimum(inliers[:, 0], len(ids_a) - 1)]
        pb = ids_b[np.minimum(inliers[:, 1], len(ids_b) - 1)]
        tied.update(zip(pa[(pa >= 0) & (pb >= 0)].tolist(), pb[(pa >= 0) & (pb >= 0)].tolist(), strict=True))
    pairs = sorted(tied)
    xyz_a = np.array([first.reconstruction.point3D(a).xyz for a, _ in pairs]).reshape(-1, 3)
    xyz_b = np.array([second.reconstruction.point3D(b).xyz for _, b in pairs]).reshape(-1, 3)
    return xyz_a, xyz_b


def _apply(similarity: np.ndarray, points: np.ndarray) -> np.ndarray:
    return np.asarray(points @ similarity[:3, :3].T + similarity[:3, 3])


def robust_similarity(
    source: np.ndarray, target: np.ndarray, max_error_m: float
) -> tuple[pycolmap.Sim3d, int] | None:
    """target_from_source by LO-RANSAC (seeded: reproducible) and its inlier count; None when none found."""
    options = pycolmap.RANSACOptions(max_error=max_error_m, random_seed=0)
    found: Any = pycolmap.estimate_sim3d_robust(source, target, options)  # a dict, whatever the stub says
    if found is None:
        return None
    return found["tgt_from_src"], int(found["num_inliers"])


def estimate_similarity(
    source: np.ndarray, target: np.ndarray, config: MergeConfig
) -> tuple[np.ndarray, int] | None:
    """4x4 target_from_source similarity by LO-RANSAC and its inlier count; None when too few points or
    the result is implausible for clips that already share the metric odometry frame."""
    if len(source) < config.min_correspondences:
        return None
    found = robust_similarity(source, target, config.max_error_m)
    if found is None:
        return None
    estimate, inliers = found
    similarity = np.eye(4)
    similarity[:3, :] = estimate.matrix()
    scale = float(estimate.scale)
    angle = np.degrees(estimate.rotation.angle())
    shift = np.linalg.norm(_apply(similarity, source.mean(axis=0, keepdims=True)) - source.mean(axis=0))
    plausible = (
        abs(scale - 1) <= config.max_scale_change
        and angle <= config.max_rotation_deg
        and shift <= config.max_shift_m
    )
    if inliers < config.min_correspondences or not plausible:
        logger.info(
            "similarity rejected: %d inliers, scale %.3f, %.2f deg, %.2f m", inliers, scale, angle, shift
        )
        return None
    return similarity, inliers


def _pairwise(
    clips: Sequence[ClipModel], matches: Sequence[tuple[str, str, np.ndarray]]
) -> dict[tuple[int, int], Correspondences]:
    """Correspondences of every ordered clip pair (both directions, from one computation per pair)."""
    found: dict[tuple[int, int], Correspondences] = {}
    for i, first in enumerate(clips):
        for j in range(i + 1, len(clips)):
            xyz_i, xyz_j = clip_correspondences(first, clips[j], matches)
            found[(i, j)], found[(j, i)] = (xyz_i, xyz_j), (xyz_j, xyz_i)
    return found


def _to_aligned(
    k: int, aligned: dict[int, Alignment], pairs: dict[tuple[int, int], Correspondences]
) -> tuple[np.ndarray, np.ndarray, int | None]:
    """Clip k's points (its own frame) and the aligned clips' points (in the merged frame) they match; the main
    partner."""
    sources, targets, best, best_n = [], [], None, 0
    for j, alignment in aligned.items():
        xyz_k, xyz_j = pairs[(k, j)]
        sources.append(xyz_k)
        targets.append(_apply(alignment.world_from_clip, xyz_j))
        if len(xyz_k) > best_n:
            best, best_n = j, len(xyz_k)
    return np.concatenate(sources), np.concatenate(targets), best


def _align_to(
    scene: str,
    source: np.ndarray,
    target: np.ndarray,
    reference: str | None,
    config: MergeConfig,
    prior: np.ndarray,
) -> tuple[Alignment, np.ndarray]:
    """The clip's alignment to the already aligned clips (`source`: its points, in its own frame): by their
    shared points, judged from where `prior` puts the clip and, when that is refused and the prior moved it, from
    where the clip stands (a wrong prior, e.g. a height tied to a road under a bridge, must not cost the clip
    the points that would place it); else its own poses moved by `prior`. Returns the alignment and the start it
    was judged from (the placement the clip keeps when its group is recentred)."""
    starts = [prior] if np.array_equal(prior, np.eye(4)) else [prior, np.eye(4)]
    for start in starts:
        moved = _apply(start, source)
        estimate = estimate_similarity(moved, target, config)
        if estimate is None:
            continue
        similarity, inliers = estimate
        centre = moved.mean(axis=0)
        shift = float(np.linalg.norm(_apply(similarity, centre[None])[0] - centre))
        return Alignment(scene, reference, "points", inliers, similarity @ start, shift), start
    return Alignment(scene, reference, "poses", len(source), prior), prior


def align_clips(
    clips: Sequence[ClipModel],
    matches: Sequence[tuple[str, str, np.ndarray]],
    config: MergeConfig,
    priors: Sequence[np.ndarray] | None = None,
) -> list[Alignment]:
    """One alignment per clip (clip order): clips tied by shared points are aligned, most overlap first, to
    the clip with the most registered images; the others keep their odometry frame. `priors` (clip order,
    4x4 world_from_clip; identity by default) move the clips before that: the similarity's plausibility
    (`max_shift_m`, ...) is judged from there (then, if refused, from the clip's own frame), and a clip aligned by
    poses keeps its prior."""
    priors = [np.eye(4)] * len(clips) if priors is None else list(priors)
    if len(priors) != len(clips):
        raise ValueError(f"align_clips: {len(priors)} priors for {len(clips)} clips")
    pairs = _pairwise(clips, matches)
    aligned: dict[int, Alignment] = {}
    remaining = sorted(range(len(clips)), key=lambda i: -clips[i].reconstruction.num_reg_images())
    while remaining:
        gathered = {k: _to_aligned(k, aligned, pairs) for k in remaining} if aligned else {}
        k = max(remaining, key=lambda i: len(gathered[i][0])) if gathered else remaining[0]
        if not gathered or len(gathered[k][0]) == 0:
            k = remaining[0]
            aligned[k] = Alignment(clips[k].scene, None, "poses", 0, priors[k])
        else:
            source, target, partner = gathered[k]
            reference = clips[partner].scene if partner is not None else None
            aligned[k], priors[k] = _align_to(clips[k].scene, source, target, reference, config, priors[k])
        remaining.remove(k)
        logger.info("clip %s: aligned by %s to %s", clips[k].scene, aligned[k].method, aligned[k].reference)
    return recentre_groups(clips, [aligned[i] for i in range(len(clips))], priors)


def _group_correction(members: list[tuple[ClipModel, Alignment, np.ndarray]]) -> np.ndarray:
    """4x4 rigid correction of a group: undoes the image-weighted mean rotation of its alignments (about the
    group's centre), then the mean shift of its cameras, so the group keeps its clips' mean placement (each
    clip where its prior put it)."""
    weights = np.array([len(clip.views) for clip, _, _ in members], dtype=np.float64)
    rotvecs = np.array(
        [
            Rotation.from_matrix((a.world_from_clip @ np.linalg.inv(prior))[:3, :3] / a.scale).as_rotvec()
            for _, a, prior in members
        ]
    )
    unrotate = Rotation.from_rotvec(-(weights[:, None] * rotvecs).sum(axis=0) / weights.sum()).as_matrix()
    own = np.concatenate([_apply(prior, own_of(clip)) for clip, _, prior in members])
    moved = np.concatenate([_apply(a.world_from_clip, own_of(clip)) for clip, a, _ in members])
    centre = moved.mean(axis=0)
    correction = np.eye(4)
    correction[:3, :3] = unrotate
    correction[:3, 3] = centre - unrotate @ centre + (own.mean(axis=0) - centre)
    return correction


def recentre_groups(
    clips: Sequence[ClipModel], alignments: list[Alignment], priors: Sequence[np.ndarray]
) -> list[Alignment]:
    """Each merged group moved as a whole so that it keeps its clips' mean placement (each moved by its
    prior): relative placement from the shared points, mean rotation and position from the clips themselves
    (odometry-anchored), rather than all inherited from the reference clip."""
    by_scene = {
        clip.scene: (clip, alignment, prior)
        for clip, alignment, prior in zip(clips, alignments, priors, strict=True)
    }
    recentred = {a.scene: a for a in alignments}
    for group in merge_groups(alignments):
        if len(group) < 2:
            continue
        correction = _group_correction([by_scene[scene] for scene in group])
        for scene in group:
            alignment = recentred[scene]
            recentred[scene] = replace(alignment, world_from_clip=correction @ alignment.world_from_clip)
    return [recentred[a.scene] for a in alignments]


def own_of(clip: ClipModel) -> np.ndarray:
    """(N, 3) camera centres of the clip's views in its own frame."""
    return np.array([v.center for v in clip.views]).reshape(-1, 3)


def merge_groups(alignments: Sequence[Alignment]) -> list[list[str]]:
    """Clips joined by point alignments, as lists of scenes (singletons for clips aligned by poses only)."""
    group_of = {a.scene: a.scene for a in alignments}

    def root(scene: str) -> str:
        while group_of[scene] != scene:
            scene = group_of[scene]
        return scene

    for alignment in alignments:
        if alignment.method == "points" and alignment.reference is not None:
            group_of[root(alignment.scene)] = root(alignment.reference)
    groups: dict[str, list[str]] = {}
    for alignment in alignments:
        groups.setdefault(root(alignment.scene), []).append(alignment.scene)
    return list(groups.values())


def aligned_views(views: Sequence[CameraView], world_from_clip: np.ndarray) -> list[CameraView]:
    """The views moved by a similarity: rotation and position of each ego pose (extrinsics stay metric)."""
    scale = float(np.cbrt(np.linalg.det(world_from_clip[:3, :3])))
    rotation = world_from_clip[:3, :3] / scale
    moved = []
    for view in views:
        world_from_ego = np.eye(4)
        world_from_ego[:3, :3] = rotation @ view.world_from_ego[:3, :3]
        world_from_ego[:3, 3] = _apply(world_from_clip, view.world_from_ego[:3, 3][None])[0]
        moved.append(replace(view, world_from_ego=world_from_ego))
    return moved
