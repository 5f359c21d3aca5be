"""Where the surface is weakly observed: what the surface report says about its observation raster.

A cell's observation count is how many keyframe rays landed on it. A cell seen by one or two rays takes its colour
and class from those alone (a parked car's shadow, one frame's motion blur), and its height from the elevation MLP's
extrapolation rather than from points near it. So the report lists, per site, the share of observed cells (and of
road cells) under `weak_rays` rays, and the largest connected weak regions with their area, median count and
bounding box in global metres, so that a lead knows where the map rests on little evidence before it is annotated.

Rays say where colour and class come from; heights come from the points the elevation was fitted to (the trajectory
strip and the SfM road points kept), and beyond them the fit continues like a plane. Past the ends of the drives of
a hilly site that plane runs centimetres to decimetres off the road (README: "The road's height past a grade
change"), and a map lifted to 3D there takes its heights from it. A stray point or two near a cell do not hold its
height (the fit's robust loss and its curvature prior outweigh them), so a cell counts as supported only when
`support_points` fitted points lie within `height_support_m` of it, and the report lists the observed road cells that
are not (`extrapolated_heights`): their share, the farthest such cell's distance to its `support_points`-th nearest
point, and the largest such regions.
"""

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree

from cama_pipeline.bev import RasterGeoreference
from cama_pipeline.semantics import ROAD_SURFACE_IDS


@dataclass(frozen=True)
class CoverageConfig:
    """What counts as weakly observed, and how much of it the report lists."""

    weak_rays: int = 3
    """Observed cells with fewer rays than this are weakly observed."""
    min_region_m2: float = 2.0
    """Weak regions smaller than this are counted but not listed (specks between well-observed cells)."""
    max_regions: int = 20
    """The largest weak regions listed, at most."""
    height_support_m: float = 2.0
    """Road cells with fewer than `support_points` fitted points within this distance have extrapolated heights."""
    support_points: int = 5
    """How many fitted points within `height_support_m` support a cell's height."""

    def __post_init__(self) -> None:
        if self.weak_rays < 2:
            raise ValueError(f"CoverageConfig.weak_rays must be >= 2, got {self.weak_rays}")
        if self.min_region_m2 < 0:
            raise ValueError(f"CoverageConfig.min_region_m2 must be >= 0, got {self.min_region_m2}")
        if self.max_regions < 0:
            raise ValueError(f"CoverageConfig.max_regions must be >= 0, got {self.max_regions}")
        if self.height_support_m <= 0:
            raise ValueError(f"CoverageConfig.height_support_m must be > 0, got {self.height_support_m}")
        if self.support_points < 1:
            raise ValueError(f"CoverageConfig.support_points must be >= 1, got {self.support_points}")


def _check_shapes(georeference: RasterGeoreference, **layers: np.ndarray) -> None:
    """ValueError naming the layers when any differs in shape from the georeference."""
    if any(layer.shape != georeference.shape for layer in layers.values()):
        shapes = ", ".join(f"{name} {layer.shape}" for name, layer in layers.items())
        raise ValueError(f"{shapes} and georeference {georeference.shape} differ in shape")


def _regions(
    mask: np.ndarray,
    road: np.ndarray,
    georeference: RasterGeoreference,
    config: CoverageConfig,
    median_of: tuple[str, np.ndarray],
) -> list[dict[str, Any]]:
    """The largest 8-connected regions of `mask` (at least `min_region_m2`, at most `max_regions`), largest first:
    area, the median over the region of the raster `median_of` (recorded under its name), road share and bounding
    box in global metres."""
    cell_m2 = georeference.resolution**2
    labels, found = ndimage.label(mask, structure=np.ones((3, 3), bool))
    regions: list[dict[str, Any]] = []
    if not found:
        return regions
    sizes = np.bincount(labels.ravel(), minlength=found + 1)[1:]
    order = np.argsort(-sizes, kind="stable")
    slices = ndimage.find_objects(labels)
    for index in order[: config.max_regions]:
        if sizes[index] * cell_m2 < config.min_region_m2:
            break
        rows, cols = slices[index]
        corners = georeference.global_from_pixel(
            [[cols.start - 0.5, rows.stop - 0.5], [cols.stop - 0.5, rows.start - 0.5]]
        )
        (x0, y0), (x1, y1) = corners.min(axis=0), corners.max(axis=0)
        inside = labels[rows, cols] == index + 1
        regions.append(
            {
                "area_m2": round(float(sizes[index] * cell_m2), 2),
                median_of[0]: float(np.median(median_of[1][rows, cols][inside])),
                "road_share": round(float(road[rows, cols][inside].mean()), 3),
                "global_box_m": [round(float(v), 2) for v in (x0, y0, x1, y1)],
            }
        )
    return regions


def weak_observation(
    count: np.ndarray, semantic: np.ndarray, georeference: RasterGeoreference, config: CoverageConfig
) -> dict[str, Any]:
    """The report's `weak_observation`: shares of observed and of road cells under `weak_rays` rays, and the
    largest weak regions (8-connected), largest first."""
    _check_shapes(georeference, **{"observation count": count, "semantic": semantic})
    observed = count > 0
    weak = observed & (count < config.weak_rays)
    road = observed & np.isin(semantic, ROAD_SURFACE_IDS)
    regions = _regions(weak, road, georeference, config, ("median_rays", count))
    return {
        "weak_rays": config.weak_rays,
        "observed_cells": int(observed.sum()),
        "weak_cells": int(weak.sum()),
        "weak_share": round(float(weak.sum() / max(int(observed.sum()), 1)), 4),
        "road_cells": int(road.sum()),
        "road_weak_share": round(float((weak & road).sum() / max(int(road.sum()), 1)), 4),
        "weak_regions": len(regions),
        "regions": regions,
    }


def extrapolated_heights(
    support_xy: np.ndarray,
    count: np.ndarray,
    semantic: np.ndarray,
    georeference: RasterGeoreference,
    config: CoverageConfig,
) -> dict[str, Any]:
    """The report's `extrapolated_heights`: the observed road cells whose `support_points`-th nearest point of
    `support_xy` ((N, 2) global metres: what the elevation was fitted to) lies farther than `height_support_m`,
    their share of the observed road cells, the farthest such distance, and the largest such regions (8-connected,
    with their median distance in metres), largest first. ValueError when there are fewer points than
    `support_points`."""
    _check_shapes(georeference, **{"observation count": count, "semantic": semantic})
    road = (count > 0) & np.isin(semantic, ROAD_SURFACE_IDS)
    distance = support_distance(support_xy, road, georeference, config.support_points)
    extrapolated = road & (distance > config.height_support_m)
    regions = _regions(extrapolated, road, georeference, config, ("median_distance_m", distance))
    return {
        "height_support_m": config.height_support_m,
        "support_points": config.support_points,
        "road_cells": int(road.sum()),
        "extrapolated_road_cells": int(extrapolated.sum()),
        "extrapolated_road_share": round(float(extrapolated.sum() / max(int(road.sum()), 1)), 4),
        "farthest_m": round(float(distance.max()), 2),
        "regions": regions,
    }


def support_distance(
    support_xy: np.ndarray, cells: np.ndarray, georeference: RasterGeoreference, support_points: int
) -> np.ndarray:
    """(rows, cols) metres from each of the `cells` (bool mask) to its `support_points`-th nearest point of
    `support_xy` ((N, 2) global metres), 0 elsewhere; ValueError when there are fewer points than that."""
    points = np.asarray(support_xy, float).reshape(-1, 2)
    if len(points) < support_points:
        raise ValueError(f"{len(points)} support points, fewer than support_points={support_points}")
    rows, cols = np.nonzero(cells)
    centres = georeference.global_from_pixel(np.column_stack([cols, rows]).astype(float))
    nearest, _ = cKDTree(points).query(centres, k=[support_points])
    distance = np.zeros(georeference.shape)
    distance[rows, cols] = nearest[:, 0]
    return distance
