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
MIN_PIXELS = 12
"""Components smaller than this (at the reference width) are noise, not instances."""
JOIN_FACTOR = 2.5
"""Crosswalk stripes, and the two lines of a double line, closer than this many times their own width join."""
JOIN_RANGE_PX = (2.0, 24.0)
"""... that distance clamped to this range (at the reference width)."""
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
        labels = _components(mask, max(2, round(MIN_PIXELS * scale * scale)))
        if cls in (Semantic.CROSSWALK, Semantic.LANE_MARKING):
            low, high = JOIN_RANGE_PX
            labels = _join_near(labels, JOIN_FACTOR, max(1.0, low * scale), max(1.0, high * scale))
        if cls in _CHAINED:
            labels = _chain(labels, scale, semantic.shape[1])
        _write(out, labels, int(cls))
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


def _join_near(labels: np.ndarray, factor: float, min_px: float, max_px: float) -> np.ndarray:
    """Components that come within `factor` times their own thickness (area / length; clamped to
    [`min_px`, `max_px`]) of another share its label: a crosswalk's stripes and a double line's two lines,
    whose gaps are about one stripe or line width, while separate lines lie many widths apart."""
    count = int(labels.max())
    if count < 2:
        return labels
    parent = list(range(count + 1))

    def root(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    height, width = labels.shape
    for piece in range(1, count + 1):
        ys, xs = np.nonzero(labels == piece)
        centred = np.column_stack([xs, ys]).astype(float)
        centred -= centred.mean(axis=0)
        length = np.ptp(centred @ np.linalg.svd(centred, full_matrices=False)[2][0]) + 1.0
        radius = int(round(min(max(factor * len(xs) / length, min_px), max_px)))
        x0, x1 = max(xs.min() - radius, 0), min(xs.max() + radius + 1, width)
        y0, y1 = max(ys.min() - radius, 0), min(ys.max() + radius + 1, height)
        own = (labels[y0:y1, x0:x1] == piece).astype(np.uint8)
        kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))
        touched = np.unique(labels[y0:y1, x0:x1][cv2.dilate(own, kernel) > 0])
        for other in touched[(touched > 0) & (touched != piece)]:
            parent[root(int(other))] = root(piece)
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


def _ends(labels: np.ndarray) -> list[_End]:
    """Both ends of every piece: the extremes of its outline along its edge axis (`_edge_axis`), each end's
    direction that of the outline's quarter nearest it (a solid line may curve)."""
    ends: list[_End] = []
    for piece in np.unique(labels[labels > 0]):
        ys, xs = np.nonzero(labels == piece)
        x0, y0 = int(xs.min()), int(ys.min())
        crop = (labels[y0 : ys.max() + 1, x0 : xs.max() + 1] == piece).astype(np.uint8)
        contours, _ = cv2.findContours(crop, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
        outline = max(contours, key=len).reshape(-1, 2).astype(float) + (x0, y0)
        axis = _edge_axis(outline)
        if axis is None:
            continue
        t = (outline - outline.mean(axis=0)) @ axis
        span = float(t.max() - t.min())
        for sign in (-1.0, 1.0):
            outward = sign * t - float((sign * t).max())  # 0 at this end, negative inwards
            tip = outline[outward >= -max(1.0, 0.1 * span)].mean(axis=0)
            quarter = np.nonzero(outward >= -max(4.0, 0.3 * span))[0]
            local = _edge_axis(outline[quarter]) if span > 60 else None
            direction = axis if local is None else local
            direction = direction if float(direction @ (sign * axis)) >= 0 else -direction
            ends.append(_End(int(piece), tip, direction))
    return ends


def _link_cost(a: _End, b: _End, max_gap: float, max_offset: float, cos_turn: float) -> float:
    """How well end `b` continues end `a` (smaller is better); inf when it does not."""
    gap = b.point - a.point
    distance = float(np.linalg.norm(gap))
    if a.piece == b.piece or distance > max_gap:
        return float("inf")
    if float(-a.direction @ b.direction) < cos_turn:  # ends of one line point at each other
        return float("inf")
    allowed = max_offset + OFFSET_PER_GAP * distance
    if distance > 1e-6:
        if float(gap @ a.direction) < -allowed or float(-gap @ b.direction) < -allowed:
            return float("inf")  # the other piece lies behind this end, not ahead of it
    off_a = abs(float(gap[0] * a.direction[1] - gap[1] * a.direction[0]))
    off_b = abs(float(gap[0] * b.direction[1] - gap[1] * b.direction[0]))
    if max(off_a, off_b) > allowed:
        return float("inf")
    return distance + 4.0 * (off_a + off_b)


def _chain(labels: np.ndarray, scale: float, width_px: int) -> np.ndarray:
    """Pieces joined into lines: each end links to its best continuing end when that one's best is it too."""
    count = int(labels.max())
    if count < 2:
        return labels
    ends = _ends(labels)
    max_gap = MAX_GAP_SHARE * width_px
    cos_turn = float(np.cos(np.radians(MAX_TURN_DEG)))
    cost = np.array(
        [[_link_cost(a, b, max_gap, MAX_OFFSET_PX * scale, cos_turn) for b in ends] for a in ends]
    ).reshape(len(ends), len(ends))
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


def _write(out: np.ndarray, labels: np.ndarray, cls: int) -> None:
    """Write one class's labels into `out` as `cls * 1000 + index`, indices 1.. by decreasing size (a class
    holds at most 999 instances; the smallest beyond that are dropped)."""
    ids, sizes = np.unique(labels[labels > 0], return_counts=True)
    ranked = ids[np.argsort(-sizes, kind="stable")][: INSTANCE_ID_BASE - 1]
    lookup = np.zeros(int(labels.max()) + 1, np.uint16)
    lookup[ranked] = cls * INSTANCE_ID_BASE + np.arange(1, len(ranked) + 1)
    values = lookup[labels]
    out[values > 0] = values[values > 0]
