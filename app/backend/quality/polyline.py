"""Polylines indexed for the lint: arc-length interpolation, projection and segment crossings in O(log n).

shapely's `line_interpolate_point` and `line_locate_point` walk the whole line for every distance or point
(GEOS's linear referencing is linear in the vertex count), so sampling a 5,000-vertex divider every 2 m and
projecting the samples onto a neighbour cost 60 ms per pair, and `shapely.node` plus a loop over the noded parts
cost seconds per line that crosses itself many times. A `Polyline` keeps its cumulative arc length
(interpolation is a binary search) and an STRtree over chunks of consecutive segments (projection is a nearest-
chunk query, then that chunk's segments in numpy; crossings are chunk pairs, then segment pairs). Interpolation
and projection follow GEOS's rules (a negative distance counts from the end, the first of equally near segments
wins, the same floating-point formulas), so they agree with shapely's to the last bit; lines of a few segments
are left to shapely, whose walk is then the cheaper.
"""

from collections.abc import Iterator
from functools import cached_property

import numpy as np
import shapely
from shapely.geometry.base import BaseGeometry

CHUNK_SEGMENTS = 8
"""Consecutive segments per indexed chunk: the tree stays small (n / 8 entries) and a chunk's segments are
checked in one numpy step (8 was fastest for projection on dense, long and winding lines alike)."""
SHORT_LINE_SEGMENTS = 32
"""Up to this many segments, interpolation and projection go to shapely (its walk along so few segments costs
less than numpy's per-call overhead); longer lines use the arc length and the index."""
PAIR_BLOCK = 4096
"""Most chunk pairs expanded to segment pairs at a time (4096 x 8 x 8 candidates), which bounds the memory."""
ROUNDING_MARGIN = 1e-13
"""Relative margin on an orientation test for it to be certain (well above float64 rounding): only segment
pairs that certainly do not meet are left out before GEOS intersects the rest."""


def _certainly_apart(p0: np.ndarray, p1: np.ndarray, q0: np.ndarray, q1: np.ndarray) -> np.ndarray:
    """Rows where segment q0-q1 lies certainly on one side of the line through p0-p1 (both orientations of the
    same sign, each beyond its rounding error)."""
    scale = np.maximum.reduce(
        [np.abs(p0).max(axis=1), np.abs(p1).max(axis=1), np.abs(q0).max(axis=1), np.abs(q1).max(axis=1)]
    )
    sides = []
    for q in (q0, q1):
        ab, aq = p1 - p0, q - p0
        left, right = ab[:, 0] * aq[:, 1], ab[:, 1] * aq[:, 0]
        error = ROUNDING_MARGIN * (
            np.abs(left) + np.abs(right) + scale * (np.abs(ab).sum(axis=1) + np.abs(aq).sum(axis=1))
        )
        det = left - right
        sides.append((det > error, det < -error))
    return (sides[0][0] & sides[1][0]) | (sides[0][1] & sides[1][1])


def _point_segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """GEOS `Distance::pointToSegment` for rows of points p and segments a-b (same formulas, same rounding)."""
    ab = b - a
    len2 = ab[:, 0] * ab[:, 0] + ab[:, 1] * ab[:, 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        r = ((p[:, 0] - a[:, 0]) * ab[:, 0] + (p[:, 1] - a[:, 1]) * ab[:, 1]) / len2
        s = ((a[:, 1] - p[:, 1]) * ab[:, 0] - (a[:, 0] - p[:, 0]) * ab[:, 1]) / len2
    to_a, to_b = p - a, p - b
    dist_a = np.sqrt(to_a[:, 0] * to_a[:, 0] + to_a[:, 1] * to_a[:, 1])
    dist_b = np.sqrt(to_b[:, 0] * to_b[:, 0] + to_b[:, 1] * to_b[:, 1])
    inner = np.abs(s) * np.sqrt(len2)
    degenerate = (a[:, 0] == b[:, 0]) & (a[:, 1] == b[:, 1])
    return np.where(degenerate | (r <= 0.0), dist_a, np.where(r >= 1.0, dist_b, inner))


class Polyline:
    """An open polyline's (n, 2) points with their arc length and a chunked segment index (built on first use)."""

    def __init__(self, points: np.ndarray) -> None:
        self.points = np.ascontiguousarray(np.asarray(points, dtype=float)[:, :2])
        if len(self.points) < 2:
            raise ValueError(f"a polyline needs >= 2 points, got {len(self.points)}")
        delta = np.diff(self.points, axis=0)
        self.segment_m = np.sqrt(delta[:, 0] * delta[:, 0] + delta[:, 1] * delta[:, 1])
        self.cumulative_m = np.concatenate([[0.0], np.cumsum(self.segment_m)])
        """Arc length at each vertex, summed in order as GEOS sums a line's length."""
        self.length_m = float(self.cumulative_m[-1])

    @property
    def segment_count(self) -> int:
        return len(self.segment_m)

    @cached_property
    def chunk_start(self) -> np.ndarray:
        """Index of the first segment of each chunk."""
        return np.arange(0, self.segment_count, CHUNK_SEGMENTS)

    @cached_property
    def chunk_tree(self) -> shapely.STRtree:
        """STRtree over the chunks (each a line of up to CHUNK_SEGMENTS segments, sharing its end vertex)."""
        ends = np.minimum(self.chunk_start + CHUNK_SEGMENTS, self.segment_count) + 1
        sizes = ends - self.chunk_start
        vertex = np.concatenate([np.arange(s, e) for s, e in zip(self.chunk_start, ends, strict=True)])
        chunks = shapely.linestrings(self.points[vertex], indices=np.repeat(np.arange(len(sizes)), sizes))
        return shapely.STRtree(chunks)

    def _chunk_segments(self, chunks: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Row k of the first array lists the segments of chunks[k] (padded); the second says which are real."""
        segments = self.chunk_start[chunks][:, None] + np.arange(CHUNK_SEGMENTS)[None, :]
        return segments, segments < self.segment_count

    @cached_property
    def line(self) -> shapely.LineString:
        """The points as a shapely line."""
        return shapely.LineString(self.points)

    @property
    def short(self) -> bool:
        """Whether GEOS's own walk along the line is cheaper than the index (few segments)."""
        return self.segment_count <= SHORT_LINE_SEGMENTS

    def interpolate(self, distances_m: np.ndarray) -> np.ndarray:
        """Points at arc-length distances, as `shapely.line_interpolate_point` (negative: from the end; clamped)."""
        d = np.asarray(distances_m, dtype=float)
        if self.short:
            return shapely.get_coordinates(shapely.line_interpolate_point(self.line, d)).reshape(-1, 2)
        d = np.where(d < 0.0, d + self.length_m, d)
        k = np.searchsorted(self.cumulative_m[1:], d, side="right")  # the first segment ending beyond d
        past_end = k >= self.segment_count
        k = np.minimum(k, self.segment_count - 1)
        p0, p1 = self.points[k], self.points[k + 1]
        with np.errstate(divide="ignore", invalid="ignore"):
            frac = ((d - self.cumulative_m[k]) / self.segment_m[k])[:, None]
        along = (p1 - p0) * frac + p0
        along = np.where(frac <= 0.0, p0, np.where(frac >= 1.0, p1, along))
        along = np.where((d <= 0.0)[:, None], self.points[0], along)
        return np.where(past_end[:, None], self.points[-1], along)

    def locate(self, xy: np.ndarray, max_distance_m: float) -> np.ndarray:
        """Arc-length position of the nearest point of the line to each of `xy`, as `shapely.line_locate_point`
        (the first of equally near segments); NaN where the line is farther than `max_distance_m`."""
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        located = np.full(len(xy), np.nan)
        if not len(xy):
            return located
        if self.short:
            points = shapely.points(xy)
            near = shapely.distance(self.line, points) <= max_distance_m
            located[near] = shapely.line_locate_point(self.line, points[near])
            return located
        query, chunks = self.chunk_tree.query_nearest(
            shapely.points(xy), max_distance=max_distance_m, all_matches=True
        )
        segments, real = self._chunk_segments(chunks)
        rows = np.repeat(query, CHUNK_SEGMENTS)[real.ravel()]
        segments = segments.ravel()[real.ravel()]
        distance = _point_segment_distance(xy[rows], self.points[segments], self.points[segments + 1])
        order = np.lexsort((segments, distance, rows))  # per point: nearest first, then the first segment
        first = order[np.unique(rows[order], return_index=True)[1]]
        rows, segments = rows[first], segments[first]
        p, a, b = xy[rows], self.points[segments], self.points[segments + 1]
        ab = b - a
        with np.errstate(divide="ignore", invalid="ignore"):
            r = ((p[:, 0] - a[:, 0]) * ab[:, 0] + (p[:, 1] - a[:, 1]) * ab[:, 1]) / (
                ab[:, 0] * ab[:, 0] + ab[:, 1] * ab[:, 1]
            )
        r = np.where((p == a).all(axis=1), 0.0, np.where((p == b).all(axis=1), 1.0, r))
        start, length = self.cumulative_m[segments], self.segment_m[segments]
        located[rows] = np.where(r <= 0.0, start, np.where(r <= 1.0, start + r * length, start + length))
        return located

    def intersects(self, geometry: BaseGeometry) -> bool:
        """Whether the line meets `geometry` (chunk by chunk, so a short geometry checks a few segments)."""
        if self.short:
            return bool(shapely.intersects(self.line, geometry))
        return bool(len(self.chunk_tree.query(geometry, predicate="intersects")))

    def segment_lines(self, segments: np.ndarray) -> np.ndarray:
        """The given segments as shapely lines."""
        return shapely.linestrings(np.stack([self.points[segments], self.points[segments + 1]], axis=1))

    def candidate_segment_pairs(
        self, other: "Polyline", first_block: int = PAIR_BLOCK
    ) -> Iterator[tuple[np.ndarray, np.ndarray]]:
        """Pairs (segment of self, segment of other) that may meet: in chunks that meet, with overlapping boxes,
        not certainly apart. In blocks ordered by self's chunks, growing from `first_block` chunk pairs to
        PAIR_BLOCK; with `other` self, each pair once, as a < b."""
        mine, theirs = other.chunk_tree.query(self.chunk_tree.geometries, predicate="intersects")
        if other is self:
            mine, theirs = mine[mine <= theirs], theirs[mine <= theirs]
        order = np.lexsort((theirs, mine))
        mine, theirs = mine[order], theirs[order]
        start, size = 0, first_block
        while start < len(mine):
            a, a_real = self._chunk_segments(mine[start : start + size])
            b, b_real = other._chunk_segments(theirs[start : start + size])
            start, size = start + size, min(2 * size, PAIR_BLOCK)
            shape = (len(a), CHUNK_SEGMENTS, CHUNK_SEGMENTS)
            keep = a_real[:, :, None] & b_real[:, None, :]
            a, b = np.broadcast_to(a[:, :, None], shape)[keep], np.broadcast_to(b[:, None, :], shape)[keep]
            if other is self:
                a, b = a[a < b], b[a < b]
            box_a, box_b = self._segment_boxes(a), other._segment_boxes(b)
            overlap = (box_a[:, 0] <= box_b[:, 2]) & (box_b[:, 0] <= box_a[:, 2])
            overlap &= (box_a[:, 1] <= box_b[:, 3]) & (box_b[:, 1] <= box_a[:, 3])
            a, b = a[overlap], b[overlap]
            p0, p1, q0, q1 = self.points[a], self.points[a + 1], other.points[b], other.points[b + 1]
            apart = _certainly_apart(p0, p1, q0, q1) | _certainly_apart(q0, q1, p0, p1)
            yield a[~apart], b[~apart]

    def _segment_boxes(self, segments: np.ndarray) -> np.ndarray:
        """xmin, ymin, xmax, ymax of each given segment."""
        a, b = self.points[segments], self.points[segments + 1]
        return np.concatenate([np.minimum(a, b), np.maximum(a, b)], axis=1)

    def crossings_with(self, other: "Polyline") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Where the two lines meet, segment pair by segment pair: self's segments, other's segments and the
        intersection geometries (points, or lines where segments overlap)."""
        found_a, found_b, found_meet = [], [], []
        for a, b in self.candidate_segment_pairs(other):
            meet = shapely.intersection(self.segment_lines(a), other.segment_lines(b))
            hit = ~shapely.is_empty(meet)
            found_a.append(a[hit])
            found_b.append(b[hit])
            found_meet.append(meet[hit])
        if not found_a:
            return np.empty(0, dtype=int), np.empty(0, dtype=int), np.empty(0, dtype=object)
        return np.concatenate(found_a), np.concatenate(found_b), np.concatenate(found_meet)

    def first_self_crossing(self) -> tuple[float, float] | None:
        """The first point along the line where it meets itself again (crosses, touches, or runs back over
        itself); None when it does not. Segment pairs are checked in order along the line, so a line with
        thousands of crossings stops at the first."""
        pending_a, pending_b = np.empty(0, dtype=int), np.empty(0, dtype=int)
        for a, b in self.candidate_segment_pairs(self, first_block=8):
            # blocks come in order of self's chunks: a node found before the last chunk seen is the first
            a, b = np.concatenate([pending_a, a]), np.concatenate([pending_b, b])
            if not len(a):
                continue
            settled = a < a.max() // CHUNK_SEGMENTS * CHUNK_SEGMENTS
            found = self._first_node(a[settled], b[settled])
            if found is not None:
                return found
            pending_a, pending_b = a[~settled], b[~settled]
        return self._first_node(pending_a, pending_b)

    def _first_node(self, a: np.ndarray, b: np.ndarray) -> tuple[float, float] | None:
        """The first meeting point along the line among segment pairs a < b; neighbours (b = a + 1, and the
        closing pair of a closed line) meet at their shared vertex by design and count only beyond it."""
        if not len(a):
            return None
        closing = (a == 0) & (b == self.segment_count - 1) & bool((self.points[0] == self.points[-1]).all())
        meet = shapely.intersection(self.segment_lines(a), self.segment_lines(b))
        shared = np.where(closing[:, None], self.points[0], self.points[a + 1])
        only_shared = shapely.equals(meet, shapely.points(shared))
        real = ~shapely.is_empty(meet) & ~(((b == a + 1) | closing) & only_shared)
        if not real.any():
            return None
        coords, which = shapely.get_coordinates(meet[real], return_index=True)
        start = self.points[a[real]][which]
        offset = np.sqrt(((coords - start) ** 2).sum(axis=1))
        measure = self.cumulative_m[a[real]][which] + offset
        x, y = coords[int(np.argmin(measure))]
        return (round(float(x), 9), round(float(y), 9))


def as_geometry_array(geometries: list[BaseGeometry]) -> np.ndarray:
    """Geometries as the object array STRtree.query wants (a plain empty list would be a float array)."""
    return np.array(geometries, dtype=object)
