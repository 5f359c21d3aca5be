"""The surface report's weakly observed cells and regions."""

import numpy as np
import pytest

from cama_pipeline.bev import RasterGeoreference
from cama_pipeline.semantics import Semantic
from cama_pipeline.surface.coverage import CoverageConfig, weak_observation

GEO = RasterGeoreference(origin_xy=(100.0, 50.0), resolution=0.5, width=20, height=10)


def test_weak_cells_shares_and_regions_in_global_metres() -> None:
    count = np.full((10, 20), 9, np.uint16)
    count[:, 15:] = 0  # never seen
    count[2:6, 0:4] = 1  # a weak 2 m x 2 m patch in the west: 16 cells, 4 m2
    count[8, 10] = 2  # a weak speck: counted, not listed
    semantic = np.full((10, 20), int(Semantic.ROAD), np.uint8)
    semantic[:, 2:4] = int(Semantic.BACKGROUND)
    report = weak_observation(count, semantic, GEO, CoverageConfig(weak_rays=3, min_region_m2=1.0))
    assert report["observed_cells"] == 150 and report["weak_cells"] == 17
    assert report["weak_share"] == round(17 / 150, 4)
    assert report["road_cells"] == 130 and report["road_weak_share"] == round(9 / 130, 4)
    (region,) = report["regions"]
    assert region["area_m2"] == 4.0 and region["median_rays"] == 1.0 and region["road_share"] == 0.5
    # cells' edges: columns 0-3 span x 99.75-101.75, rows 2-5 span y 49.25-47.25
    assert region["global_box_m"] == [99.75, 47.25, 101.75, 49.25]


def test_the_largest_regions_first_and_at_most_max_regions() -> None:
    count = np.full((10, 20), 9, np.uint16)
    count[0, 0:2] = 1
    count[5, 5:11] = 1
    count[9, 15:19] = 1
    semantic = np.zeros((10, 20), np.uint8)
    report = weak_observation(count, semantic, GEO, CoverageConfig(min_region_m2=0.0, max_regions=2))
    assert [r["area_m2"] for r in report["regions"]] == [1.5, 1.0]
    assert report["road_weak_share"] == 0.0  # no road cell at all


def test_bad_input_is_named() -> None:
    with pytest.raises(ValueError, match="differ in shape"):
        weak_observation(np.zeros((3, 3)), np.zeros((10, 20)), GEO, CoverageConfig())
    with pytest.raises(ValueError, match="weak_rays"):
        CoverageConfig(weak_rays=1)
