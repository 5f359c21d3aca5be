"""Lane instances from a semantic mask: what the generator's `lane_instance/` masks hold, recovered from labels.

The generator's instance masks give each map element its own value `class * 1000 + index` (0 = none): a curb
strip per road boundary, a lane marking per divider (all dashes of a dashed line share it) and a crosswalk per
pedestrian crossing (all its stripes). SRE (`cama_pipeline.evaluate.sre`) matches one image instance with one
projected map element, so a dashed line split into dashes would match only one of them.

Here: connected components per class (8-connected, specks dropped); crosswalk stripes closer than a few pixels
join one crossing; lane-marking and curb pieces join into one line where they continue each other: the nearer
ends of two pieces, each end's direction taken from its own part of the piece, must point at each other
(small offset across the direction, small turn), and each end takes its best such partner only when that
partner's best is this end too (so parallel lines, which converge in the image, are not chained sideways).
A straight ground line stays straight in a pinhole image and a curve turns slowly, so one-to-one chains of
continuing pieces are the lines.
"""

from dataclasses import dataclass

import cv2
import numpy as np

from cama_pipeline.semantics import INSTANCE_ID_BASE, Semantic

INSTANCE_CLASSES: tuple[Semantic, ...] = (Semantic.CURB, Semantic.LANE_MARKING, Semantic.CROSSWALK)
"""The classes the generator's instance masks hold, and so the ones given instances here."""
_CHAINED = (Semantic.CURB, Semantic.LANE_MARKING)
REFERENCE_WIDTH_PX = 512
"""The pixel sizes below are for images this wide and scale with the image width."""
MIN_PIXELS = 8
"""Instances smaller than this (at the reference width) are noise (after joining: a far dashed line is many
specks)."""
MIN_PIXELS_FLOOR = 3
"""... and smaller than this at any width (SRE leaves out instances this small anyway)."""
LOOSE_TURN_DEG = 35.0
"""How far the direction of a speck (a piece too small for its outline to tell) may turn from its partner's."""
_COS_LOOSE = float(np.cos(np.radians(LOOSE_TURN_DEG)))
SPECK_GAP_PX = 40.0
"""A speck joins only a piece within this distance (at the reference width) ..."""
SPECK_OFFSET_SHARE = 1.0 / 3.0
"""... and within this share of the usual offset of its line. Merging two map elements into one instance costs
SRE more than leaving a speck out (a merged instance matches one element with the other's pixels as error)."""
JOIN_FACTOR = 2.5
"""Crosswalk stripes, and the two lines of a double line, closer than this many times their own width join."""
JOIN_RANGE_PX = {Semantic.CROSSWALK: (2.0, 64.0), Semantic.LANE_MARKING: (2.0, 24.0)}
"""... that distance clamped to this range (at the reference width): a near crosswalk's gaps are wide, while a
double line's are narrow and other lines must stay apart."""
MAX_OFFSET_PX = 6.0
"""Two pieces continue each other only if each one's end lies within this (plus a share of the gap, below) of
the other's line."""
OFFSET_PER_GAP = 0.12
"""... plus this share of the gap between the ends (curves and the end direction's uncertainty grow with it)."""
MAX_TURN_DEG = 20.0
"""... and the two ends' directions differ by at most this."""
MAX_GAP_SHARE = 0.45
"""... and the gap is at most this share of the image width."""


@dataclass(frozen=True)
class _End:
    """One end of a piece: its point (x, y) and the unit direction pointing out of the piece."""

    piece: int
    point: np.ndarray
    direction: np.ndarray
    reliable: bool
    """From an outline long enough to tell the direction (else from a few pixels: loose, or none for one)."""


def lane_instances(semantic: np.ndarray) -> np.ndarray:
    """(H, W) uint16 instance mask (class * 1000 + index, 0 = none) of a (H, W) semantic mask (uint8 ids)."""
    if semantic.ndim != 2:
        raise ValueError(f"semantic mask must be 2D, got shape {semantic.shape}")
    scale = semantic.shape[1] / REFERENCE_WIDTH_PX
    out = np.zeros(semantic.shape, np.uint16)
    for cls in INSTANCE_CLASSES:
        mask = (semantic == int(cls)).astype(np.uint8)
        if not mask.any():
            continue
        labels = _components(mask, 2)  # far dashes are specks, yet together one line
        if cls in (Semantic.CROSSWALK, Semantic.LANE_MARKING):
            low, high = JOIN_RANGE_PX[cls]
            labels = _join_near(labels, JOIN_FACTOR, max(1.0, low * scale), max(1.0, high * scale))
        if cls in _CHAINED:
            labels = _chain(labels, semantic, scale)
        _write(out, labels, int(cls), max(MIN_PIXELS_FLOOR, round(MIN_PIXELS * scale * scale)))
    return out


def _components(mask: np.ndarray, min_pixels: int) -> np.ndarray:
    """int32 component labels (0 = none) of a binary mask, components under `min_pixels` removed."""
    count, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
    small = np.nonzero(stats[:, cv2.CC_STAT_AREA] < min_pixels)[0]
    keep = np.ones(count, bool)
    keep[small] = False
    keep[0] = False
    relabel = np.zeros(count, np.int32)
    relabel[keep] = np.arange(1, int(keep.sum()) + 1)
    return relabel[labels]


def _pixels(labels: np.ndarray) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """(rows, columns) of each piece's pixels, found in one pass over the labels."""
    ys, xs = np.nonzero(labels)
    ids = labels[ys, xs]
    order = np.argsort(ids, kind="stable")
    ids, ys, xs = ids[order], ys[order], xs[order]
    starts = np.flatnonzero(np.r_[True, ids[1:] != ids[:-1]])
    stops = np.r_[starts[1:], len(ids)]
    return {int(ids[a]): (ys[a:b], xs[a:b]) for a, b in zip(starts, stops, strict=True)}


def _reach(
    labels: np.ndarray,
    piece: int,
    pixels: tuple[np.ndarray, np.ndarray],
    factor: float,
    limits: tuple[float, float],
) -> set[int]:
    """The other pieces within `factor` times this piece's thickness (area / length, clamped to `limits`) of
    it (`pixels`: its rows and columns)."""
    min_px, max_px = limits
    ys, xs = pixels
    centred = np.column_stack([xs, ys]).astype(float)
    centred -= centred.mean(axis=0)
    length = float(np.ptp(centred @ np.linalg.svd(centred, full_matrices=False)[2][0])) + 1.0
    radius = int(round(min(max(factor * len(xs) / length, min_px), max_px)))
    height, width = labels.shape
    x0, x1 = max(xs.min() - radius, 0), min(xs.max() + radius + 1, width)
    y0, y1 = max(ys.min() - radius, 0), min(ys.max() + radius + 1, height)
    window = labels[y0:y1, x0:x1]
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))
    touched = np.unique(window[cv2.dilate((window == piece).astype(np.uint8), kernel) > 0])
    return {int(t) for t in touched if t > 0 and t != piece}


def _join_near(labels: np.ndarray, factor: float, min_px: float, max_px: float) -> np.ndarray:
    """Pieces that each lie within the other's reach (`_reach`) share a label: a crosswalk's stripes and a double
    line's two lines, whose gaps are about one stripe or line width, while separate lines lie many widths apart
    (and a big near stripe does not reach over to a small far crossing that does not reach back)."""
    count = int(labels.max())
    if count < 2:
        return labels
    reach = {
        piece: _reach(labels, piece, pixels, factor, (min_px, max_px))
        for piece, pixels in _pixels(labels).items()
    }
    parent = list(range(count + 1))

    def root(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for piece, near in reach.items():
        for other in near:
            if piece in reach[other]:
                parent[root(other)] = root(piece)
    mapping = np.array([root(i) for i in range(count + 1)], np.int32)
    return mapping[labels]


def _edge_axis(contour: np.ndarray) -> np.ndarray | None:
    """The direction most of a piece's outline runs along (unit, sign arbitrary), None for too short an outline.

    A marking's long sides run along its line; its caps are cut across the road, which in the image may be far
    from square to the line, so the principal axis of a thick dash's pixels tilts towards its caps. The mode of
    the outline's direction (5 degree bins, weighted by length) is the long sides' direction."""
    if len(contour) < 6:
        return None
    steps = np.roll(contour, -3, axis=0) - contour
    lengths = np.linalg.norm(steps, axis=1)
    angles = np.mod(np.arctan2(steps[:, 1], steps[:, 0]), np.pi)
    bins = np.minimum((angles / np.pi * 36).astype(int), 35)
    histogram = np.bincount(bins, weights=lengths, minlength=36)
    smooth = histogram + 0.5 * (np.roll(histogram, 1) + np.roll(histogram, -1))
    mode = (int(smooth.argmax()) + 0.5) * np.pi / 36
    near = np.abs(np.angle(np.exp(2j * (angles - mode)))) < np.radians(20)
    doubled = np.sum(lengths[near] * np.exp(2j * angles[near]))
    angle = float(np.angle(doubled)) / 2 if abs(doubled) > 0 else mode
    return np.array([np.cos(angle), np.sin(angle)])


def _speck_ends(piece: int, pts: np.ndarray) -> list[_End]:
    """The ends of a piece too small for its outline to give a direction: its pixels' extremes along their
    principal axis (no direction for a single pixel)."""
    if len(pts) < 2:
        return [_End(piece, pts[0], np.zeros(2), False)] * 2
    axis = np.linalg.svd(pts - pts.mean(axis=0), full_matrices=False)[2][0]
    t = (pts - pts.mean(axis=0)) @ axis
    return [_End(piece, pts[t.argmin()], -axis, False), _End(piece, pts[t.argmax()], axis, False)]


def _ends(labels: np.ndarray) -> list[_End]:
    """Both ends of every piece: the extremes of its outline along its edge axis (`_edge_axis`), each end's
    direction that of the outline's quarter nearest it (a solid line may curve); specks: `_speck_ends`."""
    ends: list[_End] = []
    for piece, (ys, xs) in _pixels(labels).items():
        x0, y0 = int(xs.min()), int(ys.min())
        crop = (labels[y0 : ys.max() + 1, x0 : xs.max() + 1] == piece).astype(np.uint8)
        contours, _ = cv2.findContours(crop, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
        outline = max(contours, key=len).reshape(-1, 2).astype(float) + (x0, y0)
        axis = _edge_axis(outline)
        t = (outline - outline.mean(axis=0)) @ axis if axis is not None else np.zeros(1)
        span = float(t.max() - t.min())
        if axis is None or span < 6.0:
            ends.extend(_speck_ends(int(piece), np.column_stack([xs, ys]).astype(float)))
            continue
        for sign in (-1.0, 1.0):
            outward = sign * t - float((sign * t).max())  # 0 at this end, negative inwards
            tip = outline[outward >= -max(1.0, 0.1 * span)].mean(axis=0)
            quarter = np.nonzero(outward >= -max(4.0, 0.3 * span))[0]
            local = _edge_axis(outline[quarter]) if span > 60 else None
            direction = axis if local is None else local
            direction = direction if float(direction @ (sign * axis)) >= 0 else -direction
            ends.append(_End(int(piece), tip, direction, True))
    return ends


def _link_cost(
    a: _End, b: _End, max_gap: float, max_offset: float, cos_turn: float, speck_gap: float
) -> float:
    """How well end `b` continues end `a` (smaller is better); inf when it does not. Offsets across the line
    are measured from the ends whose direction is reliable; between two specks, from the gap itself."""
    gap = b.point - a.point
    distance = float(np.linalg.norm(gap))
    if a.piece == b.piece or distance > max_gap:
        return float("inf")
    both = a.reliable and b.reliable
    if not both:  # a speck: near, and closer to the line (far specks of neighbouring lines crowd together)
        if distance > speck_gap:
            return float("inf")
        max_offset = max_offset * SPECK_OFFSET_SHARE
    turn = float(-a.direction @ b.direction)  # ends of one line point at each other
    if (both and turn < cos_turn) or (a.direction.any() and b.direction.any() and turn < _COS_LOOSE):
        return float("inf")
    allowed = max_offset + OFFSET_PER_GAP * distance
    guides = [(e, s) for e, s in ((a, 1.0), (b, -1.0)) if e.reliable]
    if not guides and distance > 1e-6:  # two specks: each one's axis must run along the gap
        unit = gap / distance
        if any(e.direction.any() and abs(float(unit @ e.direction)) < _COS_LOOSE for e in (a, b)):
            return float("inf")
        return 2.0 * distance
    offsets = []
    for end, sign in guides:
        if float(sign * gap @ end.direction) < -allowed:
            return float("inf")  # the other piece lies behind this end, not ahead of it
        offsets.append(abs(float(gap[0] * end.direction[1] - gap[1] * end.direction[0])))
    if max(offsets, default=0.0) > allowed:
        return float("inf")
    return distance + 4.0 * sum(offsets) * (2 if len(offsets) == 1 else 1)


def _crosses_crosswalk(semantic: np.ndarray, a: np.ndarray, b: np.ndarray) -> bool:
    """Whether the straight gap from `a` to `b` runs over crosswalk paint: lines end before a crossing and
    those beyond it are other map elements."""
    steps = max(2, int(np.ceil(np.linalg.norm(b - a))))
    t = np.linspace(0.0, 1.0, steps)[:, None]
    points = np.round(a + t * (b - a)).astype(int)
    return bool((semantic[points[:, 1], points[:, 0]] == int(Semantic.CROSSWALK)).any())


def _chain(labels: np.ndarray, semantic: np.ndarray, scale: float) -> np.ndarray:
    """Pieces joined into lines: each end links to its best continuing end when that one's best is it too."""
    count = int(labels.max())
    if count < 2:
        return labels
    ends = _ends(labels)
    max_gap = MAX_GAP_SHARE * semantic.shape[1]
    cos_turn = float(np.cos(np.radians(MAX_TURN_DEG)))
    points = np.array([end.point for end in ends])
    reliable = np.array([end.reliable for end in ends])
    gaps = np.linalg.norm(points[:, None] - points[None], axis=2)
    reach = np.where(reliable[:, None] & reliable[None], max_gap, SPECK_GAP_PX * scale)
    cost = np.full((len(ends), len(ends)), np.inf)
    for i, j in zip(*np.nonzero(gaps <= reach), strict=True):  # only pairs near enough to be linked
        cost[i, j] = _link_cost(
            ends[i], ends[j], max_gap, MAX_OFFSET_PX * scale, cos_turn, SPECK_GAP_PX * scale
        )
    for i, j in zip(*np.nonzero(np.isfinite(cost)), strict=True):
        if i < j and _crosses_crosswalk(semantic, ends[i].point, ends[j].point):
            cost[i, j] = cost[j, i] = np.inf
    best = np.where(np.isfinite(cost).any(axis=1), cost.argmin(axis=1), -1)
    parent = list(range(count + 1))

    def root(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for i, j in enumerate(best):
        if j >= 0 and best[j] == i and i < j:
            parent[root(ends[i].piece)] = root(ends[j].piece)
    mapping = np.array([root(i) for i in range(count + 1)], np.int32)
    return mapping[labels]


def _write(out: np.ndarray, labels: np.ndarray, cls: int, min_pixels: int) -> None:
    """Write one class's labels of at least `min_pixels` into `out` as `cls * 1000 + index`, indices 1.. by
    decreasing size (a class holds at most 999 instances; the smallest beyond that are dropped)."""
    ids, sizes = np.unique(labels[labels > 0], return_counts=True)
    ranked = ids[np.argsort(-sizes, kind="stable")]
    ranked = ranked[sizes[np.argsort(-sizes, kind="stable")] >= min_pixels][: INSTANCE_ID_BASE - 1]
    lookup = np.zeros(int(labels.max()) + 1, np.uint16)
    lookup[ranked] = cls * INSTANCE_ID_BASE + np.arange(1, len(ranked) + 1)
    values = lookup[labels]
    out[values > 0] = values[values > 0]
