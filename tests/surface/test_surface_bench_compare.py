"""`bench/surface.py`'s comparison reads the surface's height offset near the track (the pose frame's, which
`bench/surface_split.py --poses sfm` adds to the true heights) apart from the error at range."""

import numpy as np
import pytest

from bench.surface import NEAR_TRAJECTORY_M, compare
from cama_pipeline.bev import BevRasters, RasterGeoreference
from cama_pipeline.semantics import Semantic


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
