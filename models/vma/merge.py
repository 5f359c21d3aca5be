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
from shapely.geometry import LineString, Polygon

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
    """Keep vectors in descending score order unless a kept same-class vector already covers them."""
    kept: list[Vector] = []
    for vector in sorted(vectors, key=lambda v: -v.score):
        rivals = [k for k in kept if k.cls == vector.cls]
        if vector.closed:
            shape = Polygon(vector.points).buffer(0)
            duplicate = any(_iou(shape, Polygon(k.points).buffer(0)) > config.duplicate_iou for k in rivals)
        else:
            duplicate = any(_covered_share(vector, k, config.duplicate_m) > 0.8 for k in rivals)
        if not duplicate:
            kept.append(vector)
    return kept


def _iou(a: Polygon, b: Polygon) -> float:
    union = a.union(b).area
    return float(a.intersection(b).area / union) if union > 0 else 0.0


def _covered_share(vector: Vector, other: Vector, distance_m: float) -> float:
    """Share of `vector`'s points (every 0.5 m) within `distance_m` of `other`."""
    line, target = LineString(vector.points), LineString(other.points)
    stations = np.linspace(0, line.length, max(2, int(line.length / 0.5)))
    return float(np.mean([target.distance(line.interpolate(s)) <= distance_m for s in stations]))


def join_polylines(
    items: list[tuple[np.ndarray, float]], max_gap_m: float, max_angle_deg: float
) -> list[tuple[np.ndarray, float]]:
    """Greedily join polylines whose ends face each other across a gap <= max_gap_m, nearest gap first.

    Each item is (points, score); a joined polyline's score is the length-weighted mean of its parts.
    """
    paths = [(np.asarray(p, dtype=np.float64), float(s)) for p, s in items]
    cos_limit = float(np.cos(np.radians(max_angle_deg)))
    while True:
        best = _best_join([p for p, _ in paths], max_gap_m, cos_limit)
        if best is None:
            return paths
        i, j, flip_i, flip_j = best
        (a, sa), (b, sb) = paths[i], paths[j]
        a, b = (a[::-1] if flip_i else a), (b[::-1] if flip_j else b)
        la, lb = _length(a), _length(b)
        paths[i] = (np.vstack([a, b]), (sa * la + sb * lb) / max(la + lb, 1e-9))
        del paths[j]


def _length(points: np.ndarray) -> float:
    return float(np.linalg.norm(np.diff(points, axis=0), axis=1).sum())


def _best_join(
    paths: list[np.ndarray], max_gap_m: float, cos_limit: float
) -> tuple[int, int, bool, bool] | None:
    """(i, j, reverse i, reverse j) of the closest aligned end pair: i's end meets j's start.

    Ends are numbered 2 * path + (0 for the start, 1 for the end); all pairs are tested at once.
    """
    if len(paths) < 2:
        return None
    ends = [_end(p, tail=t) for p in paths for t in (False, True)]
    pos = np.array([e[0] for e in ends])
    out = np.array([e[1] for e in ends])
    gap = pos[None, :, :] - pos[:, None, :]  # from end a to end b
    dist = np.linalg.norm(gap, axis=2)
    unit = gap / np.maximum(dist, 1e-9)[..., None]
    facing = -(out @ out.T) >= cos_limit
    along = ((unit * out[:, None, :]).sum(2) >= cos_limit) & (-(unit * out[None, :, :]).sum(2) >= cos_limit)
    owner = np.arange(len(ends)) // 2
    ok = (dist <= max_gap_m) & facing & (along | (dist <= _NEAR_M)) & (owner[:, None] != owner[None, :])
    if not ok.any():
        return None
    a, b = np.unravel_index(np.argmin(np.where(ok, dist, np.inf)), dist.shape)
    # path of end a must finish at a (reverse it when a is its start); path of end b must begin at b
    return int(owner[a]), int(owner[b]), bool(a % 2 == 0), bool(b % 2 == 1)


def _end(path: np.ndarray, *, tail: bool) -> tuple[np.ndarray, np.ndarray]:
    """An end point of a path and its outward unit direction (measured over the last ~1 m)."""
    pts = path if tail else path[::-1]  # pts[-1] is the end in question
    back = pts[::-1]
    lengths = np.cumsum(np.linalg.norm(np.diff(back, axis=0), axis=1))
    k = min(int(np.searchsorted(lengths, 1.0)) + 1, len(back) - 1)
    direction = back[0] - back[k]
    norm = float(np.linalg.norm(direction))
    return back[0], direction / norm if norm > 0 else np.array([1.0, 0.0])
