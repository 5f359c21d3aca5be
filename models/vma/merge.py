"""Merging per-window predictions into site vectors: core clipping, joining across borders, de-duplication.

Sliding windows overlap; each window owns a core (the cells nearer its centre than any other window's),
and the cores tile the site. Polylines are clipped to their window's core, so every stretch of a line is
kept from the window that saw it best-centred; pieces whose ends meet across a core border are joined
(confidence: length-weighted mean); rings (crosswalks) are kept by the window whose core holds their
centroid. Remaining duplicates (two queries on one line) are removed by score-ordered suppression.
"""

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import shapely
from scipy.spatial import cKDTree
from shapely.geometry import LineString, Polygon

from annotations.geometry import resample_fixed
from models.vma.vectors import Vector, clip_vectors

_NEAR_M = 0.5
"""Ends closer than this join whatever the direction of the (tiny) gap between them."""


@dataclass(frozen=True)
class MergeConfig:
    """How window predictions become site vectors."""

    join_gap_m: float = 1.5
    """Largest end-to-end gap joined across a window border."""
    join_angle_deg: float = 45.0
    """Largest direction change across a joined gap."""
    duplicate_m: float = 0.75
    """A line lying within this distance of a better-scored same-class line (80% of it) is a duplicate."""
    duplicate_iou: float = 0.4
    """A ring overlapping a better-scored ring by this IoU is a duplicate."""
    min_length_m: float = 1.0

    def __post_init__(self) -> None:
        if min(self.join_gap_m, self.duplicate_m, self.duplicate_iou) <= 0 or self.min_length_m < 0:
            raise ValueError("MergeConfig: gaps, distances and IoU must be > 0, min_length_m >= 0")


def core_bounds(centres: Sequence[float], index: int) -> tuple[float, float]:
    """The 1D core of window `index` among sorted window centres: halfway to each neighbour (open at the ends)."""
    lo = -np.inf if index == 0 else (centres[index - 1] + centres[index]) / 2
    hi = np.inf if index == len(centres) - 1 else (centres[index] + centres[index + 1]) / 2
    return float(lo), float(hi)


def clip_to_core(
    vectors: Sequence[Vector], core: tuple[float, float, float, float], min_length_m: float
) -> list[Vector]:
    """Lines clipped to the core (xmin, xmax, ymin, ymax); rings kept whole when their centroid is inside."""
    xmin, xmax, ymin, ymax = (float(np.clip(v, -1e9, 1e9)) for v in core)
    out = clip_vectors([v for v in vectors if not v.closed], (xmin, xmax, ymin, ymax), min_length_m)
    for ring in (v for v in vectors if v.closed):
        cx, cy = ring.points[:-1].mean(axis=0)
        if xmin <= cx < xmax and ymin <= cy < ymax:
            out.append(ring)
    return out


def merge_windows(vectors: Sequence[Vector], config: MergeConfig | None = None) -> list[Vector]:
    """Join core-clipped lines across borders per class, then suppress duplicates."""
    config = config or MergeConfig()
    merged: list[Vector] = []
    for cls in sorted({v.cls for v in vectors}):
        same = [v for v in vectors if v.cls == cls]
        if same and same[0].closed:
            merged += same
            continue
        items = join_polylines([(v.points, v.score) for v in same], config.join_gap_m, config.join_angle_deg)
        merged += [Vector(cls, p, s) for p, s in items]
    return suppress_duplicates([v for v in merged if v.length_m() >= config.min_length_m], config)


def suppress_duplicates(vectors: Sequence[Vector], config: MergeConfig) -> list[Vector]:
    """Keep vectors in descending score order unless a kept same-class vector already covers them.

    Only kept vectors whose bounding boxes come within `duplicate_m` are compared.
    """
    kept: list[Vector] = []
    boxes: list[np.ndarray] = []
    for vector in sorted(vectors, key=lambda v: -v.score):
        box = np.concatenate([vector.points.min(axis=0), vector.points.max(axis=0)])
        rivals = [
            k
            for k, b in zip(kept, boxes, strict=True)
            if k.cls == vector.cls
            and (b[:2] <= box[2:] + config.duplicate_m).all()
            and (box[:2] <= b[2:] + config.duplicate_m).all()
        ]
        if vector.closed:
            shape = Polygon(vector.points).buffer(0)
            duplicate = any(_iou(shape, Polygon(k.points).buffer(0)) > config.duplicate_iou for k in rivals)
        else:
            duplicate = any(_covered_share(vector, k, config.duplicate_m) > 0.8 for k in rivals)
        if not duplicate:
            kept.append(vector)
            boxes.append(box)
    return kept


def _iou(a: Polygon, b: Polygon) -> float:
    union = a.union(b).area
    return float(a.intersection(b).area / union) if union > 0 else 0.0


def _covered_share(vector: Vector, other: Vector, distance_m: float) -> float:
    """Share of `vector`'s points (about every 0.5 m) within `distance_m` of `other`."""
    samples = resample_fixed(vector.points, max(2, int(vector.length_m() / 0.5)))
    return float(np.mean(shapely.distance(LineString(other.points), shapely.points(samples)) <= distance_m))


def join_polylines(
    items: list[tuple[np.ndarray, float]], max_gap_m: float, max_angle_deg: float
) -> list[tuple[np.ndarray, float]]:
    """Join polylines whose ends face each other across a gap <= max_gap_m, nearest gaps first.

    Each item is (points, score); a joined polyline's score is the length-weighted mean of its parts.
    Candidate end pairs are found once (k-d tree) and linked greedily by distance, each end at most once
    and never closing a loop, so the cost grows with the number of nearby ends, not its cube.
    """
    paths = [np.asarray(p, dtype=np.float64) for p, _ in items]
    scores = [float(s) for _, s in items]
    links = _links(paths, max_gap_m, float(np.cos(np.radians(max_angle_deg))))
    out: list[tuple[np.ndarray, float]] = []
    seen: set[int] = set()
    starts = [i for i in range(len(paths)) if 2 * i not in links or 2 * i + 1 not in links]
    for first in starts:
        if first in seen:
            continue
        parts, entry = [], 2 * first if 2 * first not in links else 2 * first + 1
        while True:
            path = entry // 2
            seen.add(path)
            forward = entry % 2 == 0
            parts.append(path if forward else -path - 1)
            exit_end = entry + 1 if forward else entry - 1
            if exit_end not in links:
                break
            entry = links[exit_end]
        pieces = [paths[k] if k >= 0 else paths[-k - 1][::-1] for k in parts]
        weights = [_length(p) for p in pieces]
        score = sum(scores[k if k >= 0 else -k - 1] * w for k, w in zip(parts, weights, strict=True))
        out.append(
            (np.vstack(pieces), score / max(sum(weights), 1e-9) if sum(weights) > 0 else scores[first])
        )
    return out


def _links(paths: list[np.ndarray], max_gap_m: float, cos_limit: float) -> dict[int, int]:
    """Greedy end-to-end links (end a <-> end b, both directions in the dict), nearest aligned pairs first.

    Ends are numbered 2 * path + (0 for the start, 1 for the end).
    """
    if len(paths) < 2:
        return {}
    ends = [_end(p, tail=t) for p in paths for t in (False, True)]
    pos = np.array([e[0] for e in ends])
    out_dir = np.array([e[1] for e in ends])
    candidates = []
    for a, b in cKDTree(pos).query_pairs(max_gap_m):
        if a // 2 == b // 2 or -(out_dir[a] @ out_dir[b]) < cos_limit:
            continue
        gap = pos[b] - pos[a]
        dist = float(np.linalg.norm(gap))
        if dist > _NEAR_M and (
            (gap / dist) @ out_dir[a] < cos_limit or -((gap / dist) @ out_dir[b]) < cos_limit
        ):
            continue
        candidates.append((dist, a, b))
    parent = list(range(len(paths)))

    def root(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    links: dict[int, int] = {}
    for _, a, b in sorted(candidates):
        if a in links or b in links or root(a // 2) == root(b // 2):
            continue
        links[a], links[b] = b, a
        parent[root(a // 2)] = root(b // 2)
    return links


def _length(points: np.ndarray) -> float:
    return float(np.linalg.norm(np.diff(points, axis=0), axis=1).sum())


def _end(path: np.ndarray, *, tail: bool) -> tuple[np.ndarray, np.ndarray]:
    """An end point of a path and its outward unit direction (measured over the last ~1 m)."""
    pts = path if tail else path[::-1]  # pts[-1] is the end in question
    back = pts[::-1]
    lengths = np.cumsum(np.linalg.norm(np.diff(back, axis=0), axis=1))
    k = min(int(np.searchsorted(lengths, 1.0)) + 1, len(back) - 1)
    direction = back[0] - back[k]
    norm = float(np.linalg.norm(direction))
    return back[0], direction / norm if norm > 0 else np.array([1.0, 0.0])
