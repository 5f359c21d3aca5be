"""Carrying a proposal's ends along rays over the semantic raster, to where the road's evidence says they end.

Paint detection stops short of where a map element really ends: the last dashes of a lane line fade at the
edge of what the cameras saw, and a zebra crossing's outer stripes stop up to a stripe period short of the
kerbs it runs between. These helpers walk the raster from an end, outwards, cell by cell (global metres in,
global metres out) and say how far the road goes on.
"""

import numpy as np

from cama_pipeline.semantics import ROAD_SURFACE_IDS, Semantic
from models.vma.rasters import SiteRasters

ALONG_ROAD_IDS = (int(Semantic.ROAD), int(Semantic.LANE_MARKING))
"""Cells a lane line may run over."""
OFF_ROAD_IDS = (int(Semantic.CURB), int(Semantic.BACKGROUND))
"""Observed ground beside the road."""
UNSEEN_RUN_M = 1.0
"""Unobserved cells count as the edge of what was seen when they go on for this long (not a speck)."""


def cells_at(rasters: SiteRasters, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Raster cells of global points: rows, columns (nearest cell, possibly outside) and whether inside."""
    colrow = np.rint(rasters.pixel_from_global(xy)).astype(int)
    h, w = rasters.shape
    inside = (colrow[:, 0] >= 0) & (colrow[:, 0] < w) & (colrow[:, 1] >= 0) & (colrow[:, 1] < h)
    return colrow[:, 1], colrow[:, 0], inside


def labels_at(rasters: SiteRasters, xy: np.ndarray) -> np.ndarray:
    """Semantic ids at global points. Outside the raster: unobserved when the raster marks unobserved cells (a
    reconstruction's raster spans what was seen), else -1 (a map raster that simply ends there)."""
    rows, cols, inside = cells_at(rasters, xy)
    unseen_outside = bool((rasters.semantic == int(Semantic.UNOBSERVED)).any())
    labels = np.full(len(xy), int(Semantic.UNOBSERVED) if unseen_outside else -1, np.int64)
    labels[inside] = rasters.semantic[rows[inside], cols[inside]]
    return labels


def _ray(rasters: SiteRasters, start: np.ndarray, direction: np.ndarray, length_m: float) -> np.ndarray:
    """Points every cell from `start` (excluded) along the unit `direction` for `length_m`."""
    stations = np.arange(rasters.resolution_m, length_m, rasters.resolution_m)
    return start + np.outer(stations, direction)


def extend_to_unseen(points: np.ndarray, rasters: SiteRasters, max_m: float) -> np.ndarray:
    """`points` with each end carried on along its direction to the first unobserved cells, when those begin
    within `max_m` and every cell on the way is road or lane marking (not a crossing, curb or off-road)."""
    run = round(UNSEEN_RUN_M / rasters.resolution_m)
    for _ in range(2):
        points = points[::-1]
        along = points[-1] - _point_back(points, 1.0)
        norm = float(np.linalg.norm(along))
        if norm == 0:
            continue
        samples = _ray(rasters, points[-1], along / norm, max_m + UNSEEN_RUN_M)
        labels = labels_at(rasters, samples)
        unseen = labels == int(Semantic.UNOBSERVED)
        for k in np.flatnonzero(unseen[: round(max_m / rasters.resolution_m)]):
            if not np.isin(labels[:k], ALONG_ROAD_IDS).all():
                break
            if unseen[k : k + run].mean() >= 0.8:
                if k > 0:
                    points = np.vstack([points, samples[k - 1]])
                break
    return points


def _point_back(points: np.ndarray, distance_m: float) -> np.ndarray:
    """The vertex at least `distance_m` back from the last one along the polyline (the first if none)."""
    gaps = np.linalg.norm(points[-1] - points[::-1], axis=1)
    far = np.flatnonzero(gaps >= distance_m)
    return points[::-1][far[0]] if far.size else points[0]


def road_left(
    rasters: SiteRasters, start: np.ndarray, direction: np.ndarray, max_m: float, reach_m: float
) -> float | None:
    """How far the road goes on from `start` along `direction` before its edge: the distance to the first
    cell that is not road, when that is within `max_m` and observed off-road ground (curb or sidewalk) lies
    within `reach_m` beyond it (a thin unobserved strip at a kerb is bridged); None when unknown."""
    labels = labels_at(rasters, _ray(rasters, start, direction, max_m + reach_m))
    off = np.flatnonzero(~np.isin(labels, ROAD_SURFACE_IDS))
    if off.size == 0 or off[0] * rasters.resolution_m > max_m:
        return None
    beyond = labels[off[0] : off[0] + round(reach_m / rasters.resolution_m) + 1]
    if not np.isin(beyond, OFF_ROAD_IDS).any():
        return None
    return (off[0] + 0.5) * rasters.resolution_m
