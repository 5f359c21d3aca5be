"""The rule-based proposer: semantic raster -> class masks -> skeletons -> simplified polylines with confidence.

The cold-start proposer of the paper and the baseline the learned model must beat. Lane markings give
dividers (double lines closed into one, dashes joined along their direction, kinks tighter than a lane line
bends dropped, ends carried on to the edge of what was seen when the road goes on to it), curbs give
boundaries, and crosswalk stripes closed into blocks give `ped_crossing` rectangles, carried on across the road
to its edge (crossings run kerb to kerb; their outer stripes stop short). Boundaries come from the curb label's
skeleton, or (`boundary_source="road_edge"`, for reconstructed rasters) from the edge of the road (road, marking
or crosswalk cells) where observed off-road ground (curb or background) is near: on reconstructed rasters the
curb's vertical face smears its label over the sidewalk, leaves it out in places (the road meets the sidewalk
directly) and hides a thin strip beside it, while the road's edge stays sharp. Where the road runs into
unobserved cells (the end of what the cameras saw) there is no boundary; the short hook a boundary's skeleton
takes round that corner is cut off, and the line lies on the edge between the road and its rim cells.
Confidence is mask support: the share of a vector's length with its mask nearby (bridged dash gaps lower it),
damped for short vectors.
"""

import logging
from dataclasses import dataclass
from typing import Literal

import cv2
import numpy as np
from shapely.geometry import LineString

from annotations.geometry import arc_lengths
from cama_pipeline.semantics import ROAD_SURFACE_IDS, Semantic
from models.vma.merge import join_polylines
from models.vma.raster_rays import OFF_ROAD_IDS, cells_at, extend_to_unseen, road_left
from models.vma.rasters import SiteRasters
from models.vma.skeleton_paths import skeleton_paths
from models.vma.vectors import Vector

logger = logging.getLogger(__name__)

BoundarySource = Literal["curb", "road_edge"]
"""Which raster evidence boundaries follow (see `RuleConfig.boundary_source`)."""


@dataclass(frozen=True)
class RuleConfig:
    """Settings of the rule-based proposer (metres, converted to pixels by the raster's resolution)."""

    close_line_m: float = 0.4
    """Closing radius that merges a double line into one stroke."""
    close_crosswalk_m: float = 0.8
    """Closing radius that merges zebra stripes into one block."""
    join_gap_m: float = 7.0
    """Largest gap between aligned pieces joined into one divider (dash gaps)."""
    join_angle_deg: float = 20.0
    """Largest direction change across a joined gap."""
    join_boundary_gap_m: float = 1.5
    """Largest gap joined between boundary pieces (curbs have no dashes; this bridges noise breaks)."""
    divider_min_radius_m: float = 10.0
    """Lane lines bend no tighter than this: a vertex whose turn, with its neighbours, has a smaller radius is a
    kink (a speck of marking label stuck to the line pulls the skeleton aside) and is dropped."""
    extend_to_unseen_m: float = 7.0
    """A divider whose paint stops this close to unobserved cells, over road all the way, runs on to them:
    beyond the last dash the cameras read, a lane line goes on to the edge of what they saw (the dash gap
    `join_gap_m` bridges between pieces)."""
    min_length_m: float = 2.0
    """Shorter polylines are dropped."""
    boundary_source: BoundarySource = "curb"
    """Boundaries along the curb label ('curb': generator rasters, where it is one sharp band) or along the
    road's edge next to observed off-road ground ('road_edge': reconstructed rasters, where the curb label is
    smeared or missing)."""
    curb_reach_m: float = 1.0
    """'road_edge': the road's edge is a boundary where a curb or background cell lies within this distance of
    it (bridging the thin unobserved strip beside a curb)."""
    hook_m: float = 1.5
    """'road_edge': an end stretch up to this long that turns away by more than `hook_angle_deg` is cut off
    (the road's edge rounding the corner into unobserved cells; real curbs turn with a radius of metres)."""
    hook_angle_deg: float = 45.0
    road_hole_m2: float = 4.0
    """Non-road pieces inside the road smaller than this are label noise, not islands with a boundary."""
    min_crosswalk_area_m2: float = 4.0
    crosswalk_reach_m: float = 1.5
    """A crossing runs from kerb to kerb while its outer stripes stop up to a stripe period short: its block
    is carried on across the road to the road's edge when that lies within this distance."""
    min_blob_m2: float = 0.1
    """Mask pieces smaller than this are noise and removed before skeletonising."""
    min_piece_m: float = 0.5
    """Skeleton pieces shorter than this are dropped before joining."""
    simplify_m: float = 0.1
    """Douglas-Peucker tolerance."""
    support_radius_m: float = 0.4
    """A vector point is supported when its class mask lies within this distance."""
    full_confidence_length_m: float = 10.0
    """Vectors at least this long keep their full support as confidence; shorter ones are damped."""

    def __post_init__(self) -> None:
        if self.boundary_source not in ("curb", "road_edge"):
            raise ValueError(
                f"RuleConfig.boundary_source must be 'curb' or 'road_edge', got {self.boundary_source!r}"
            )
        for name, value in self.__dict__.items():
            if name != "boundary_source" and not value > 0:
                raise ValueError(f"RuleConfig.{name} must be > 0, got {value}")


def propose_rule_based(rasters: SiteRasters, config: RuleConfig | None = None) -> list[Vector]:
    """Dividers, boundaries and crosswalks of a site from its semantic raster, global metres, with confidence."""
    config = config or RuleConfig()
    semantic = rasters.semantic
    road = road_mask(semantic, rasters.resolution_m, config)
    vectors = [
        *_line_vectors(
            rasters, semantic == int(Semantic.LANE_MARKING), "divider", config, config.join_gap_m, road
        ),
        *_line_vectors(
            rasters,
            _boundary_mask(semantic, road, rasters.resolution_m, config),
            "boundary",
            config,
            config.join_boundary_gap_m,
            road,
        ),
        *crosswalk_vectors(rasters, semantic == int(Semantic.CROSSWALK), config),
    ]
    logger.info("rule-based proposer: %d vectors on %s", len(vectors), rasters.name)
    return vectors


def _disk(radius_px: float) -> np.ndarray:
    size = 2 * max(1, round(radius_px)) + 1
    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (size, size))


def _line_vectors(
    rasters: SiteRasters, mask: np.ndarray, cls: str, config: RuleConfig, join_gap_m: float, road: np.ndarray
) -> list[Vector]:
    """Skeleton polylines of one class mask; aligned pieces joined across gaps up to `join_gap_m` (`road`: the
    site's road mask, which road-edge boundaries are moved towards)."""
    res = rasters.resolution_m
    closed = cv2.morphologyEx(mask.astype(np.uint8), cv2.MORPH_CLOSE, _disk(config.close_line_m / res))
    closed = remove_small_blobs(closed, round(config.min_blob_m2 / res**2))
    min_pixels = max(2, round(config.min_piece_m / res))
    paths = [rasters.global_from_pixel(p) for p in skeleton_paths(closed > 0, min_pixels)]
    joined = join_polylines([(p, 1.0) for p in paths], join_gap_m, config.join_angle_deg)
    paths = [p for p, _ in joined]
    support = cv2.dilate(mask.astype(np.uint8), _disk(config.support_radius_m / res)) > 0
    out = []
    for path in paths:
        points = np.asarray(LineString(path).simplify(config.simplify_m).coords)
        if cls == "boundary" and config.boundary_source == "road_edge":
            points = trim_hooks(points, config.hook_m, config.hook_angle_deg)
            points = _half_cell_toward_road(points, rasters, road)
        if cls == "divider":
            points = drop_kinks(points, config.divider_min_radius_m)
            points = extend_to_unseen(points, rasters, config.extend_to_unseen_m)
        line = LineString(points)
        if line.length < config.min_length_m:
            continue
        out.append(Vector(cls, points, _confidence(rasters, support, points, config)))
    return out


def _boundary_mask(
    semantic: np.ndarray, road: np.ndarray, resolution_m: float, config: RuleConfig
) -> np.ndarray:
    if config.boundary_source == "road_edge":
        return road_edge(semantic, road, resolution_m, config)
    return semantic == int(Semantic.CURB)


def road_mask(semantic: np.ndarray, resolution_m: float, config: RuleConfig) -> np.ndarray:
    """Road, marking and crosswalk cells (uint8), with small non-road holes in it (label noise) filled."""
    road = np.isin(semantic, ROAD_SURFACE_IDS).astype(np.uint8)
    holes = (1 - road) & (1 - remove_small_blobs(1 - road, round(config.road_hole_m2 / resolution_m**2)))
    return road | holes


def _half_cell_toward_road(points: np.ndarray, rasters: SiteRasters, road: np.ndarray) -> np.ndarray:
    """A polyline along rim cells moved half a cell towards the side the road lies on (most segments' vote):
    onto the edge between the road and its rim rather than the rim cells' centres."""
    line = LineString(points)
    step = np.diff(points, axis=0)
    lengths = np.linalg.norm(step, axis=1)
    if line.length == 0 or not (lengths > 0).all():
        return points
    left = np.column_stack([-step[:, 1], step[:, 0]]) / lengths[:, None]
    middles = (points[:-1] + points[1:]) / 2
    probe = 3 * rasters.resolution_m

    def on_road(xy: np.ndarray) -> np.ndarray:
        rows, cols, _ = cells_at(rasters, xy)
        h, w = road.shape
        return road[np.clip(rows, 0, h - 1), np.clip(cols, 0, w - 1)].astype(int)

    vote = int(np.sum((on_road(middles + probe * left) - on_road(middles - probe * left)) * lengths))
    if vote == 0:
        return points
    moved = line.offset_curve(np.sign(vote) * rasters.resolution_m / 2, join_style="mitre", mitre_limit=2.0)
    return np.asarray(moved.coords) if isinstance(moved, LineString) and len(moved.coords) >= 2 else points


def road_edge(semantic: np.ndarray, road: np.ndarray, resolution_m: float, config: RuleConfig) -> np.ndarray:
    """Cells just outside the road with observed off-road ground (curb or background) within `curb_reach_m`:
    the road's boundary as a 1-cell band, at the road's sharp edge rather than along the curb label smeared
    over the sidewalk (or missing), bridging the thin unobserved strip a curb's face hides. Where the road
    runs into unobserved cells (a cut-off arm) there is none. `road`: `road_mask` of the raster."""
    off_road = np.isin(semantic, OFF_ROAD_IDS).astype(np.uint8)
    near_off_road = cv2.dilate(off_road, _disk(config.curb_reach_m / resolution_m)) > 0
    rim = (cv2.dilate(road, np.ones((3, 3), np.uint8)) > 0) & (road == 0)
    return rim & near_off_road


def drop_kinks(points: np.ndarray, min_radius_m: float) -> np.ndarray:
    """`points` without the interior vertices that turn tighter than `min_radius_m` (the radius of the circle
    through a vertex and its neighbours), sharpest first, until none does."""
    points = np.asarray(points, dtype=np.float64)
    while len(points) > 2:
        a, b, c = points[:-2], points[1:-1], points[2:]
        cross = np.abs((b - a)[:, 0] * (c - a)[:, 1] - (b - a)[:, 1] * (c - a)[:, 0])
        sides = np.linalg.norm(b - a, axis=1) * np.linalg.norm(c - b, axis=1) * np.linalg.norm(c - a, axis=1)
        radius = np.divide(sides, 2 * cross, out=np.full(len(cross), np.inf), where=cross > 0)
        k = int(np.argmin(radius))
        if radius[k] >= min_radius_m:
            break
        points = np.delete(points, k + 1, axis=0)
    return points


def trim_hooks(points: np.ndarray, hook_m: float, angle_deg: float) -> np.ndarray:
    """`points` without an end stretch (at most `hook_m` long) that turns away from the line's direction over
    the next `2 * hook_m` by more than `angle_deg`: cut at the vertex where the turn starts."""
    for _ in range(2):
        points = _trim_tail(points, hook_m, np.cos(np.radians(angle_deg)))[::-1]
    return points


def _trim_tail(points: np.ndarray, hook_m: float, cos_limit: float) -> np.ndarray:
    along = arc_lengths(points)
    total = along[-1]
    if total < 3 * hook_m:
        return points
    for k in range(1, len(points) - 1):  # candidate turn vertices, farthest from the end first
        if total - along[k] > hook_m:
            continue
        before = points[k] - points[int(np.searchsorted(along, along[k] - 2 * hook_m, side="right")) - 1]
        after = points[-1] - points[k]
        norms = float(np.linalg.norm(before) * np.linalg.norm(after))
        if norms > 0 and before @ after / norms < cos_limit:
            return points[: k + 1]
    return points


def remove_small_blobs(mask: np.ndarray, min_pixels: int) -> np.ndarray:
    """`mask` (uint8) without the 8-connected pieces of fewer than `min_pixels` cells."""
    count, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
    keep = stats[:, cv2.CC_STAT_AREA] >= min_pixels
    keep[0] = False
    return keep[labels].astype(np.uint8)


def _confidence(rasters: SiteRasters, support: np.ndarray, points: np.ndarray, config: RuleConfig) -> float:
    """Share of the polyline (sampled every 0.25 m) on supported pixels, damped when short."""
    line = LineString(points)
    stations = np.linspace(0.0, line.length, max(2, int(line.length / 0.25)))
    samples = np.array([line.interpolate(s).coords[0] for s in stations])
    rows, cols, inside = cells_at(rasters, samples)  # `support` is a mask of the raster's own cells
    hits = np.zeros(len(samples), bool)
    hits[inside] = support[rows[inside], cols[inside]]
    damping = min(1.0, line.length / config.full_confidence_length_m) ** 0.5
    return float(hits.mean() * damping)


def crosswalk_vectors(rasters: SiteRasters, mask: np.ndarray, config: RuleConfig) -> list[Vector]:
    """Rotated rectangles around the crosswalk stripe blocks of `mask`; confidence = stripe fill within the
    closed block."""
    res = rasters.resolution_m
    mask = remove_small_blobs(mask.astype(np.uint8), round(config.min_blob_m2 / res**2)) > 0
    closed = cv2.morphologyEx(mask.astype(np.uint8), cv2.MORPH_CLOSE, _disk(config.close_crosswalk_m / res))
    count, labels = cv2.connectedComponents(closed)
    out = []
    for index in range(1, count):
        rows, cols = np.nonzero(labels == index)
        if rows.size * res**2 < config.min_crosswalk_area_m2:
            continue
        rect = cv2.minAreaRect(np.column_stack([cols, rows]).astype(np.float32))
        corners = span_to_kerbs(rasters.global_from_pixel(cv2.boxPoints(rect)), mask, rasters, config)
        ring = np.vstack([corners, corners[:1]])
        block_fill = rows.size / max(1.0, rect[1][0] * rect[1][1])
        stripe_share = mask[rows, cols].mean() / 0.5  # zebra stripes cover about half of a block
        out.append(Vector("ped_crossing", ring, float(np.clip(min(block_fill, stripe_share), 0, 1))))
    return out


def span_to_kerbs(
    corners: np.ndarray, stripes: np.ndarray, rasters: SiteRasters, config: RuleConfig
) -> np.ndarray:
    """A crossing's rectangle (4 corners, global) carried on along its stripe-spacing axis (the one its stripes
    alternate along) to the road's edge at either end, where `road_left` finds one within reach."""
    centre = corners.mean(axis=0)
    axes = [corners[1] - corners[0], corners[2] - corners[1]]
    lengths = [float(np.linalg.norm(a)) for a in axes]
    if min(lengths) == 0:
        return corners
    units = [a / n for a, n in zip(axes, lengths, strict=True)]
    changes = [_alternations(stripes, rasters, centre, u, n) for u, n in zip(units, lengths, strict=True)]
    k = int(np.argmax(changes))
    across, side = units[k], units[1 - k]
    ends = []
    for sign in (1.0, -1.0):
        found = [
            road_left(
                rasters,
                centre + sign * across * lengths[k] / 2 + side * offset * lengths[1 - k],
                sign * across,
                config.crosswalk_reach_m,
                config.curb_reach_m,
            )
            for offset in (-0.25, 0.0, 0.25)
        ]
        known = [f for f in found if f is not None]
        ends.append(float(np.median(known)) if len(known) >= 2 else 0.0)
    centre = centre + across * (ends[0] - ends[1]) / 2
    half = [across * (lengths[k] + sum(ends)) / 2, side * lengths[1 - k] / 2]
    return np.array(
        [
            centre - half[0] - half[1],
            centre + half[0] - half[1],
            centre + half[0] + half[1],
            centre - half[0] + half[1],
        ]
    )


def _alternations(
    stripes: np.ndarray, rasters: SiteRasters, centre: np.ndarray, unit: np.ndarray, length: float
) -> int:
    """How often the stripe mask switches on or off along a line through `centre`."""
    stations = np.arange(-length / 2, length / 2, rasters.resolution_m)
    rows, cols, inside = cells_at(rasters, centre + np.outer(stations, unit))
    values = stripes[rows[inside], cols[inside]].astype(np.int8)
    return int(np.abs(np.diff(values)).sum())
