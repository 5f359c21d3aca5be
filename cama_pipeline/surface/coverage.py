"""Where the surface is weakly observed: what the surface report says about its observation raster.

A cell's observation count is how many keyframe rays landed on it. A cell seen by one or two rays takes its colour
and class from those alone (a parked car's shadow, one frame's motion blur), and its height from the elevation MLP's
extrapolation rather than from points near it. So the report lists, per site, the share of observed cells (and of
road cells) under `weak_rays` rays, and the largest connected weak regions with their area, median count and
bounding box in global metres, so that a lead knows where the map rests on little evidence before it is annotated.
"""

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import ndimage

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

    def __post_init__(self) -> None:
        if self.weak_rays < 2:
            raise ValueError(f"CoverageConfig.weak_rays must be >= 2, got {self.weak_rays}")
        if self.min_region_m2 < 0:
            raise ValueError(f"CoverageConfig.min_region_m2 must be >= 0, got {self.min_region_m2}")
        if self.max_regions < 0:
            raise ValueError(f"CoverageConfig.max_regions must be >= 0, got {self.max_regions}")


def weak_observation(
    count: np.ndarray, semantic: np.ndarray, georeference: RasterGeoreference, config: CoverageConfig
) -> dict[str, Any]:
    """The report's `weak_observation`: shares of observed and of road cells under `weak_rays` rays, and the
    largest weak regions (8-connected), largest first."""
    if count.shape != semantic.shape or count.shape != georeference.shape:
        raise ValueError(
            f"observation count {count.shape}, semantic {semantic.shape} and georeference {georeference.shape} "
            "differ in shape"
        )
    observed = count > 0
    weak = observed & (count < config.weak_rays)
    road = observed & np.isin(semantic, ROAD_SURFACE_IDS)
    cell_m2 = georeference.resolution**2
    labels, found = ndimage.label(weak, structure=np.ones((3, 3), bool))
    regions = []
    if found:
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
                    "median_rays": float(np.median(count[rows, cols][inside])),
                    "road_share": round(float(road[rows, cols][inside].mean()), 3),
                    "global_box_m": [round(float(v), 2) for v in (x0, y0, x1, y1)],
                }
            )
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
