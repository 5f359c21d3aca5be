"""The surface report's weakly observed cells and regions."""

from dataclasses import replace

import numpy as np
import pytest

from cama_pipeline.bev import RasterGeoreference
from cama_pipeline.semantics import Semantic
from cama_pipeline.surface.command import extrapolated_text
from cama_pipeline.surface.coverage import CoverageConfig, extrapolated_heights, weak_observation

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


def test_road_cells_far_from_every_fitted_point_have_extrapolated_heights() -> None:
    count = np.full((10, 20), 9, np.uint16)
    count[:, 18:] = 0  # never seen: not counted, however far
    semantic = np.full((10, 20), int(Semantic.ROAD), np.uint8)
    semantic[0, :] = int(Semantic.BACKGROUND)  # off-road: its height is no road's
    # points along the raster's row 5 (y = 47.5), columns 0-9 (x 100-104.5): the trajectory strip's kind
    support = np.column_stack([100.0 + 0.5 * np.arange(10), np.full(10, 47.5)])
    config = CoverageConfig(height_support_m=2.0, support_points=1, min_region_m2=0)
    report = extrapolated_heights(support, count, semantic, GEO, config)
    road = 9 * 18
    assert report["road_cells"] == road and report["support_points"] == 1
    # with one point enough, a road cell is extrapolated when more than 2 m (4 cells) from every point
    distance = np.hypot(np.maximum(np.arange(18) - 9, 0)[None, :], np.arange(1, 10)[:, None] - 5) * 0.5
    assert report["extrapolated_road_cells"] == int((distance > 2.0).sum()) > 0
    assert report["extrapolated_road_share"] == round(int((distance > 2.0).sum()) / road, 4)
    assert report["farthest_m"] == round(float(distance.max()), 2)
    (region,) = report["regions"]
    assert region["road_share"] == 1.0 and region["median_distance_m"] > 2.0
    assert region["global_box_m"][2] == 108.75  # the last observed column, 17, ends at x = 108.75


def test_a_few_stray_points_do_not_support_a_height() -> None:
    count = np.full((10, 20), 9, np.uint16)
    semantic = np.full((10, 20), int(Semantic.ROAD), np.uint8)
    strip = np.column_stack([100.0 + 0.5 * np.arange(20), np.full(20, 47.5)])  # row 5, every column
    strays = np.array([[100.0, 50.0], [100.5, 50.0]])  # two points by the north-west corner
    config = CoverageConfig(height_support_m=1.0, support_points=3, min_region_m2=0)
    alone = extrapolated_heights(strip, count, semantic, GEO, config)
    strayed = extrapolated_heights(np.vstack([strip, strays]), count, semantic, GEO, config)
    assert strayed["extrapolated_road_cells"] == alone["extrapolated_road_cells"]
    one = replace(config, support_points=1)
    assert (
        extrapolated_heights(np.vstack([strip, strays]), count, semantic, GEO, one)["extrapolated_road_cells"]
        < alone["extrapolated_road_cells"]
    )
    # three points within 1 m: on row 5 itself and on rows 4 and 6 (the third nearest 0.71 m away), but not at
    # the strip's two end columns there (1.12 m): 20 + 2 * 18 of the 200 cells are held
    assert alone["extrapolated_road_cells"] == 200 - 56


def test_too_few_support_points_and_bad_settings_are_refused() -> None:
    count = np.full((10, 20), 9, np.uint16)
    semantic = np.full((10, 20), int(Semantic.ROAD), np.uint8)
    with pytest.raises(ValueError, match="2 support points, fewer than support_points=5"):
        extrapolated_heights(np.array([[100.0, 47.5], [101.0, 47.5]]), count, semantic, GEO, CoverageConfig())
    with pytest.raises(ValueError, match="height_support_m"):
        CoverageConfig(height_support_m=0)
    with pytest.raises(ValueError, match="support_points"):
        CoverageConfig(support_points=0)
    with pytest.raises(ValueError, match="differ in shape"):
        extrapolated_heights(np.zeros((5, 2)), np.zeros((3, 3)), semantic, GEO, CoverageConfig())


def test_the_command_shows_the_extrapolated_share_and_nothing_for_an_older_report() -> None:
    report = {
        "extrapolated_road_share": 0.0312,
        "height_support_m": 2.0,
        "support_points": 5,
        "farthest_m": 7.25,
    }
    assert extrapolated_text(report) == "3.1 % (< 5 points within 2 m; up to 7.25 m)"
    assert extrapolated_text(None) == "-"  # a report written before the field existed
