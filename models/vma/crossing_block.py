"""A crossing's block read from its stripes: the axis from the stripes' edges, the width where they hold.

`rule_based.crosswalk_vectors` puts the smallest rotated rectangle round a crossing's closed stripe mask. That
rectangle answers to every stray cell: on a surface stage's rasters a few crosswalk cells smeared past a kerb
corner, or a block cut at a slant by the edge of what the cameras saw, tilt it by several degrees and widen it by
up to a metre, while the stripes themselves sit where they should (their profile along the road rises and falls
within a cell of the true block). A person reads a crossing by its stripes, and so does this fit:

- the across axis (the one the stripes alternate along) starts from the dominant direction of the stripe mask's
  gradients (a structure tensor over the block: the long sides of the stripes, not the outline of the block,
  decide it) and is refined to the angle that gives the narrowest block along the road (`sharpest_axis`); the
  rectangle's own angle is kept where it is as narrow within half a cell;
- the width along the road is where the share of observed cells that are stripe cells stands above a quarter of
  its plateau (`EDGE_LEVEL`, chosen on reconstructions 9113-9123): a block cut at a slant by the edge of what was
  seen keeps its width, and a few stray cells do not reach the level;
- the length across the road is the span of the stripe cells across (the shortest and longest 0.5 % left out),
  which `span_to_kerbs` then carries on to the kerbs as before.

Where the stripes do not show one direction clearly (coherence under `min_coherence`: a worn crossing whose
stripes merged into a blob), the caller keeps the rectangle.

The product proposes with the rectangle (`MaskInferenceConfig.crossing_fit`): this fit's saving on the
reconstructions it was chosen on did not hold on fresh ones (README, "Crossings read from their stripes").
"""

import cv2
import numpy as np

from models.vma.rasters import SiteRasters
from models.vma.rule_based import RuleConfig, span_to_kerbs

MIN_COHERENCE = 0.3
"""(l1 - l2) / (l1 + l2) of the stripes' structure tensor below which their direction is not trusted."""
SPAN_QUANTILE = 0.005
"""The share of stripe cells at either end across the road left out of the block's length (stray cells)."""
EDGE_LEVEL = 0.25
"""A block's ends along the road are where the stripes' share falls below this share of its plateau."""
SEARCH_DEG = 6.0
"""How far from the stripes' gradient direction the across axis is searched (`sharpest_axis`)."""
KEEP_PX = 0.5
"""A rectangle's axis whose block is this close to the narrowest (half a cell: not resolved) is kept."""
MARGIN_PX = 4
"""Cells round the stripes' bounding box kept for the gradients."""


def across_axis(stripes: np.ndarray) -> tuple[np.ndarray, float]:
    """The unit (col, row) direction the stripes of a bool mask alternate along, and its coherence in [0, 1]."""
    smooth = cv2.GaussianBlur(stripes.astype(np.float32), (0, 0), 1.0)
    gx = cv2.Sobel(smooth, cv2.CV_32F, 1, 0, ksize=3)
    gy = cv2.Sobel(smooth, cv2.CV_32F, 0, 1, ksize=3)
    tensor = np.array([[(gx * gx).sum(), (gx * gy).sum()], [(gx * gy).sum(), (gy * gy).sum()]], np.float64)
    values, vectors = np.linalg.eigh(tensor)
    total = float(values.sum())
    coherence = float((values[1] - values[0]) / total) if total > 0 else 0.0
    return vectors[:, 1], coherence


def plateau_span(positions: np.ndarray, observed: np.ndarray, level: float) -> tuple[float, float]:
    """(low, high) where the share of observed cells that are stripe cells rises above and falls below `level` of
    its plateau (the median of the shares above half the highest) along one axis; `positions` are the stripe cells'
    centres and `observed` the observed cells' (the stripes' among them), one bin a cell, centred on whole numbers.
    Read between bin centres, the run round the peak: at level 0.5 a block of whole cells gives its outer edges, half
    a cell past its centres (a lower level reads them that much farther out), and a block cut at a slant by the edge of what was seen keeps its width. Bins of under a quarter
    of the most observed cells count as empty."""
    low_bin = np.rint(min(positions.min(), observed.min())) - 1
    size = int(np.rint(max(positions.max(), observed.max())) - low_bin) + 2
    counts = np.bincount((np.rint(positions) - low_bin).astype(np.int64), minlength=size).astype(np.float64)
    seen = np.bincount((np.rint(observed) - low_bin).astype(np.int64), minlength=size).astype(np.float64)
    share = np.where(seen >= seen.max() / 4, counts / np.maximum(seen, 1.0), 0.0)
    plateau = float(np.median(share[share >= share.max() / 2]))
    half = plateau * level
    peak = int(np.argmax(share))
    first = peak
    while first > 0 and share[first - 1] >= half:
        first -= 1
    last = peak
    while last < len(share) - 1 and share[last + 1] >= half:
        last += 1

    def crossing(outside: int, inside: int) -> float:
        # bin k's centre is at low_bin + k; interpolate where the profile passes half between the two
        part = (half - share[outside]) / (share[inside] - share[outside])
        return float(low_bin + outside + part * (inside - outside))

    return crossing(first - 1, first), crossing(last + 1, last)


def block_width(
    cells: np.ndarray, seen: np.ndarray, across: np.ndarray, span: tuple[float, float]
) -> tuple[float, float]:
    """(low, high) of the block along the road (`plateau_span` at `EDGE_LEVEL`) for stripe `cells` and observed
    cells `seen` ((N, 2) col, row) with the given across axis, counting the observed cells within the stripes'
    `span` across."""
    along = np.array([-across[1], across[0]])
    middle, half = (span[0] + span[1]) / 2, (span[1] - span[0]) / 2
    seen = seen[np.abs(seen @ across - middle) <= half + 0.5]
    return plateau_span(cells @ along, seen @ along, EDGE_LEVEL)


def across_span(cells: np.ndarray, across: np.ndarray) -> tuple[float, float]:
    """The stripe cells' span along `across`, the shortest and longest `SPAN_QUANTILE` left out."""
    low, high = np.quantile(cells @ across, [SPAN_QUANTILE, 1 - SPAN_QUANTILE])
    return float(low), float(high)


def width_at(cells: np.ndarray, seen: np.ndarray, across: np.ndarray) -> float:
    """The block's width along the road (`block_width`) with the given across axis."""
    low, high = block_width(cells, seen, across, across_span(cells, across))
    return high - low


def sharpest_axis(
    cells: np.ndarray, seen: np.ndarray, across: np.ndarray, preferred: np.ndarray | None = None
) -> np.ndarray:
    """The across axis within `SEARCH_DEG` of `across` (0.1 degree steps) that gives the narrowest block along the
    road: a tilted axis spreads each end of the block into a ramp as long as the block times the tilt's sine,
    while the gradients' direction wanders with the raster's jagged stripe edges by a degree or two. A short block
    narrows little with the right angle, so the `preferred` axis (the rectangle's) is kept when its block is within
    `KEEP_PX` of the narrowest."""
    angle = np.arctan2(across[1], across[0])
    steps = np.radians(np.arange(-SEARCH_DEG, SEARCH_DEG + 1e-9, 0.1))
    candidates = np.column_stack([np.cos(angle + steps), np.sin(angle + steps)])
    widths = [width_at(cells, seen, candidate) for candidate in candidates]
    if preferred is not None and width_at(cells, seen, preferred) <= min(widths) + KEEP_PX:
        return preferred
    # the width is flat near its least; the middle of the angles within a tenth of a cell of it
    narrowest = np.flatnonzero(np.asarray(widths) <= min(widths) + 0.1)
    return candidates[narrowest[len(narrowest) // 2]]


def rectangle_axis(rasters: SiteRasters, ring: np.ndarray, across: np.ndarray) -> np.ndarray:
    """The side of a rectangular ring (global metres) nearest the direction `across`, as a unit (col, row) vector
    pointing the same way."""
    corners = rasters.pixel_from_global(np.asarray(ring, dtype=np.float64)[:3])
    sides = [corners[1] - corners[0], corners[2] - corners[1]]
    units = [side / max(float(np.linalg.norm(side)), 1e-9) for side in sides]
    axis = max(units, key=lambda unit: abs(float(unit @ across)))
    return axis if axis @ across >= 0 else -axis


def stripe_block(
    rasters: SiteRasters,
    stripes: np.ndarray,
    observed: np.ndarray,
    config: RuleConfig,
    *,
    rectangle: np.ndarray | None = None,
    min_coherence: float = MIN_COHERENCE,
) -> np.ndarray | None:
    """(5, 2) the closed ring (global metres) of the crossing whose stripes are the bool raster `stripes` (one
    crossing's) among the bool raster `observed` of the cells the cameras saw, fitted as the module docstring says;
    None where they show no clear direction or are empty. `rectangle` (a ring, global metres: the smallest
    rectangle round the stripes) gives the axis kept where the stripes do not show a sharper one."""
    rows, cols = np.nonzero(stripes)
    if rows.size < 2:
        return None
    r0, c0 = max(0, rows.min() - MARGIN_PX), max(0, cols.min() - MARGIN_PX)
    window = stripes[r0 : rows.max() + MARGIN_PX + 1, c0 : cols.max() + MARGIN_PX + 1]
    across, coherence = across_axis(window)
    if coherence < min_coherence:
        return None
    cells = np.column_stack([cols, rows]).astype(np.float64)
    window_seen = observed[r0 : r0 + window.shape[0], c0 : c0 + window.shape[1]]
    seen_rows, seen_cols = np.nonzero(window_seen)
    seen = np.column_stack([seen_cols + c0, seen_rows + r0]).astype(np.float64)
    across = sharpest_axis(
        cells, seen, across, None if rectangle is None else rectangle_axis(rasters, rectangle, across)
    )
    along = np.array([-across[1], across[0]])
    u0, u1 = across_span(cells, across)
    v0, v1 = block_width(cells, seen, across, (u0, u1))
    corners_px = np.array(
        [u * across + v * along for u, v in ((u0 - 0.5, v0), (u1 + 0.5, v0), (u1 + 0.5, v1), (u0 - 0.5, v1))]
    )
    corners = span_to_kerbs(rasters.global_from_pixel(corners_px), stripes, rasters, config)
    return np.vstack([corners, corners[:1]])
