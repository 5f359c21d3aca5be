"""Proposal-to-final diffs: how far an annotator moved a model proposal, the training signal for retraining.

Chamfer distance is measured between densely resampled curves (each sample to the other curve, exactly);
vertices are put in one-to-one correspondence by nearest neighbour within a tolerance to count how many were
moved, added or removed.
"""

import logging
from dataclasses import dataclass

import numpy as np
import shapely
from numpy.typing import ArrayLike
from scipy.spatial import cKDTree

from annotations.geometry import is_closed, resample_spacing, validate_geometry

logger = logging.getLogger(__name__)

UNCHANGED_TOLERANCE_M = 1e-6
"""Points closer than this count as the same; an element is unchanged when every point is."""


@dataclass(frozen=True)
class DiffConfig:
    """Sampling and matching parameters of a proposal diff, in metres."""

    sample_spacing_m: float = 0.1
    """Spacing of the dense resampling used for the Chamfer distance."""
    match_tolerance_m: float = 2.0
    """A proposal vertex and a final vertex farther apart than this are not the same vertex."""

    def __post_init__(self) -> None:
        """Reject non-positive distances."""
        for name in ("sample_spacing_m", "match_tolerance_m"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name}: must be positive, got {getattr(self, name)}")


@dataclass(frozen=True)
class ProposalDiff:
    """What changed between a proposal and its final version.

    `mean_displacement_m` is the mean distance over matched vertex pairs (0 for untouched vertices), so it is
    the average distance a proposal vertex was moved; 0 when no vertex matched.
    """

    unchanged: bool
    class_changed: bool
    chamfer_m: float
    vertices_moved: int
    vertices_added: int
    vertices_removed: int
    mean_displacement_m: float


def _vertices(points: np.ndarray) -> np.ndarray:
    """Distinct vertices: a closed ring's repeated last point dropped."""
    return points[:-1] if len(points) > 2 and is_closed(points) else points


def chamfer_distance(first: np.ndarray, second: np.ndarray, sample_spacing_m: float) -> float:
    """Symmetric Chamfer distance: mean over both directions of densely resampled points to the other curve."""
    lines = (shapely.LineString(first), shapely.LineString(second))
    total = 0.0
    for samples_of, other in ((first, lines[1]), (second, lines[0])):
        samples = shapely.points(resample_spacing(samples_of, sample_spacing_m))
        total += float(np.mean(shapely.distance(samples, other)))
    return total / 2.0


def match_vertices(first: np.ndarray, second: np.ndarray, tolerance_m: float) -> list[tuple[int, int, float]]:
    """One-to-one vertex pairs (i, j, distance) within `tolerance_m`, closest pairs first (greedy)."""
    pairs = cKDTree(first).sparse_distance_matrix(cKDTree(second), tolerance_m, output_type="ndarray")
    used_first: set[int] = set()
    used_second: set[int] = set()
    matches = []
    for record in np.sort(pairs, order=["v", "i", "j"]):
        i, j, distance = int(record["i"]), int(record["j"]), float(record["v"])
        if i not in used_first and j not in used_second:
            used_first.add(i)
            used_second.add(j)
            matches.append((i, j, distance))
    return matches


def proposal_diff(
    proposal_points: ArrayLike,
    final_points: ArrayLike,
    *,
    proposal_cls: str | None = None,
    final_cls: str | None = None,
    config: DiffConfig = DiffConfig(),  # noqa: B008 - frozen, so a shared default is safe
) -> ProposalDiff:
    """Compare a proposal with its final geometry (and class, when both are given); ValueError on bad points."""
    proposal = validate_geometry(proposal_points, closed=False, field="proposal_points")[:, :2]
    final = validate_geometry(final_points, closed=False, field="final_points")[:, :2]
    class_changed = proposal_cls is not None and final_cls is not None and proposal_cls != final_cls
    same_points = proposal.shape == final.shape and bool(
        np.all(np.abs(proposal - final) <= UNCHANGED_TOLERANCE_M)
    )
    proposal_vertices, final_vertices = _vertices(proposal), _vertices(final)
    matches = match_vertices(proposal_vertices, final_vertices, config.match_tolerance_m)
    distances = np.array([distance for _, _, distance in matches])
    diff = ProposalDiff(
        unchanged=same_points and not class_changed,
        class_changed=class_changed,
        chamfer_m=0.0 if same_points else chamfer_distance(proposal, final, config.sample_spacing_m),
        vertices_moved=int(np.sum(distances > UNCHANGED_TOLERANCE_M)),
        vertices_added=len(final_vertices) - len(matches),
        vertices_removed=len(proposal_vertices) - len(matches),
        mean_displacement_m=float(distances.mean()) if len(distances) else 0.0,
    )
    logger.debug("proposal diff: %s", diff)
    return diff
