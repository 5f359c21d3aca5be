"""Homography-guided spatial pairs: KNN over camera centres, then the HSP rules, then ground-footprint overlap."""

import logging
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from cama_pipeline.cameras import CameraView
from cama_pipeline.pairs.config import PairsConfig
from cama_pipeline.pairs.footprint import footprint_overlap, ground_footprint
from cama_pipeline.pairs.rules import face_to_face, height_compatible, view_cones_overlap
from cama_pipeline.pairs.sequential import Pair, ordered

logger = logging.getLogger(__name__)


@dataclass
class HspStats:
    """How many candidates each rule removed: the funnel reported by `cama pairs`."""

    candidates: int = 0
    dropped: dict[str, int] = field(
        default_factory=lambda: {"height": 0, "view_cone": 0, "face_to_face": 0, "footprint": 0}
    )
    kept: int = 0


def knn_candidates(views: list[CameraView], config: PairsConfig, exclude: set[Pair]) -> list[Pair]:
    """Neighbour pairs within `knn_radius_m`, among each camera's `knn` nearest (0: all within the radius),
    minus `exclude` (already paired)."""
    if len(views) < 2:
        return []
    centers = np.array([view.center for view in views])
    tree = cKDTree(centers)
    if config.knn == 0:
        found = {(int(i), int(j)) for i, j in tree.query_pairs(config.knn_radius_m)}
    else:
        k = min(config.knn + 1, len(views))
        distances, neighbours = tree.query(centers, k=k, distance_upper_bound=config.knn_radius_m)
        found = {
            ordered(i, int(j))
            for i, (row_d, row_j) in enumerate(zip(distances, neighbours, strict=True))
            for d, j in zip(row_d, row_j, strict=True)
            if np.isfinite(d) and int(j) != i
        }
    return sorted(found - exclude)


def rule_verdicts(
    views: list[CameraView],
    candidates: list[Pair],
    config: PairsConfig,
    height_offsets: Mapping[str, float] | None = None,
) -> np.ndarray:
    """(N,) the name of the first rule that rejects each candidate ("height", "view_cone", "face_to_face"),
    or "" for the ones that pass; all candidates at once. `height_offsets`: metres added to the camera heights
    of a scene's views (`free_height_offsets`)."""
    verdicts = np.full(len(candidates), "", dtype=object)
    if not candidates:
        return verdicts
    centers = np.array([view.center for view in views])
    if height_offsets:
        centers[:, 2] += [height_offsets.get(view.scene, 0.0) for view in views]
    axes = np.array([view.axis for view in views])
    first, second = np.array(candidates).T
    ca, cb, aa, ab = centers[first], centers[second], axes[first], axes[second]
    facing = face_to_face(
        ca,
        aa,
        cb,
        ab,
        min_angle_deg=config.face_to_face_angle_deg,
        max_distance_m=config.face_to_face_max_distance_m,
    )
    verdicts[facing] = "face_to_face"
    verdicts[~view_cones_overlap(ca, aa, cb, ab)] = "view_cone"
    verdicts[~height_compatible(ca, cb, config.max_dz_m)] = "height"  # last write wins: the first rule
    return verdicts


def footprint_overlaps(views: list[CameraView], pairs: list[Pair], config: PairsConfig) -> np.ndarray:
    """(len(pairs),) `footprint_overlap` of each pair, footprints traced once per camera."""
    if not pairs:
        return np.zeros(0)
    used = sorted({index for pair in pairs for index in pair})
    polygons = {
        index: ground_footprint(views[index], config.footprint_grid, config.footprint_max_range_m)
        for index in used
    }
    first = np.array([polygons[i] for i, _ in pairs], dtype=object)
    second = np.array([polygons[j] for _, j in pairs], dtype=object)
    return footprint_overlap(first, second)


def spatial_pairs(
    views: list[CameraView],
    config: PairsConfig,
    exclude: set[Pair],
    skip: set[int] | None = None,
    height_offsets: Mapping[str, float] | None = None,
) -> tuple[dict[Pair, str], HspStats]:
    """HSP pairs not already in `exclude` and not involving a view of `skip`, with the funnel of what each
    rule removed; `height_offsets` as `rule_verdicts` takes them."""
    stats = HspStats()
    candidates = knn_candidates(views, config, exclude)
    if skip:
        candidates = [(i, j) for i, j in candidates if i not in skip and j not in skip]
    verdicts = rule_verdicts(views, candidates, config, height_offsets)
    stats.candidates = len(candidates)
    for rule in ("height", "view_cone", "face_to_face"):
        stats.dropped[rule] = int((verdicts == rule).sum())
    survivors = [pair for pair, verdict in zip(candidates, verdicts, strict=True) if verdict == ""]
    overlaps = footprint_overlaps(views, survivors, config)
    pairs = {
        pair: "hsp"
        for pair, share in zip(survivors, overlaps, strict=True)
        if share >= config.min_footprint_overlap
    }
    stats.dropped["footprint"] = len(survivors) - len(pairs)
    stats.kept = len(pairs)
    logger.info("HSP: %d candidates, dropped %s, kept %d", stats.candidates, stats.dropped, stats.kept)
    return pairs, stats
