"""`bench/surface.py`'s comparison reads the surface's height offset near the track (the pose frame's, which
`bench/surface_split.py --poses sfm` adds to the true heights) apart from the error at range."""

import numpy as np
import pytest

from bench.surface import NEAR_TRAJECTORY_M, compare, height_error_by_support
from cama_pipeline.bev import BevRasters, RasterGeoreference
from cama_pipeline.semantics import Semantic
from cama_pipeline.surface.coverage import CoverageConfig


def _rasters(geo: RasterGeoreference, elevation: np.ndarray) -> BevRasters:
    semantic = np.full(geo.shape, int(Semantic.ROAD), np.uint8)
    photometric = np.full((*geo.shape, 3), 100, np.uint8)
    return BevRasters(
        geo, semantic=semantic, photometric_rgb=photometric, elevation=elevation.astype(np.float32)
    )


def test_the_offset_near_the_track_is_read_apart_from_the_error_at_range() -> None:
    geo = RasterGeoreference(origin_xy=(0.0, 20.0), resolution=0.1, width=200, height=401)
    rows, _ = np.indices(geo.shape)
    y = 20.0 - 0.1 * rows  # the track runs along y = 0
    truth = _rasters(geo, np.zeros(geo.shape))
    # 3 cm high everywhere (the frame's offset), and a further 10 cm beyond 8 m from the track
    ours = _rasters(geo, 0.03 + 0.10 * (np.abs(y) > 8.0))
    trajectory = np.column_stack([np.arange(0.0, 20.0, 0.5), np.zeros(40)])
    figures = compare(ours, truth, trajectory, np.zeros(geo.shape, np.float32))
    assert NEAR_TRAJECTORY_M < 8.0
    assert figures["elevation_median_signed_m_near_trajectory"] == pytest.approx(0.03, abs=1e-6)
    assert figures["elevation_median_signed_m"] == pytest.approx(0.13, abs=1e-6)  # most cells lie beyond 8 m
    bands = figures["elevation_rmse_m_by_distance_from_trajectory_m"]
    assert bands["0-2"] == pytest.approx(0.03, abs=1e-6) and bands["14-100"] == pytest.approx(0.13, abs=1e-6)


def test_the_height_error_is_split_where_the_report_calls_heights_extrapolated() -> None:
    geo = RasterGeoreference(origin_xy=(0.0, 20.0), resolution=0.1, width=200, height=401)
    rows, _ = np.indices(geo.shape)
    y = 20.0 - 0.1 * rows
    count = np.full(geo.shape, 5, np.uint16)
    truth = _rasters(geo, np.zeros(geo.shape))
    elevation = 0.03 + 0.10 * (np.abs(y) > 8.0)  # the frame's 3 cm, and 10 cm off beyond 8 m from the points
    ours = BevRasters(
        geo,
        semantic=truth.require("semantic"),
        photometric_rgb=truth.require("photometric"),
        elevation=elevation.astype(np.float32),
        observation_count=count,
    )
    # fitted points on a grid every 0.5 m within 6 m of the track: supported to 6 m and a little beyond
    xs, ys = np.meshgrid(np.arange(0.0, 20.0, 0.5), np.arange(-6.0, 6.01, 0.5))
    support = np.column_stack([xs.ravel(), ys.ravel()])
    coverage = CoverageConfig(height_support_m=2.0, support_points=5)
    split = height_error_by_support(ours, truth, support, coverage, offset_m=0.03)
    assert split["supported"]["rmse_m"] == pytest.approx(0.0, abs=1e-6)  # the offset taken out, nothing left
    assert split["extrapolated"]["rmse_m"] > 0.09  # mostly the cells beyond 8 m
    assert split["extrapolated"]["cells"] + split["supported"]["cells"] == 401 * 200
