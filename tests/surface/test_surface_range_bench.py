"""`bench/surface_range.py` splits the road's height error by distance from the camera track and reads the true
terrain's curvature across it."""

import numpy as np
import pytest

from bench.surface_range import BANDS_M, band_figures, lateral_curvature, true_elevation, without_offset
from cama_pipeline.bev import BevRasters, RasterGeoreference
from cama_pipeline.semantics import Semantic


def test_errors_are_split_by_band_after_the_offset_near_the_track() -> None:
    distance = np.array([1.0, 3.0, 5.0, 5.5, 13.0])
    error = np.array([0.02, 0.02, 0.03, 0.07, 0.12])  # 2 cm high near the track: the frame's offset
    flat = without_offset(distance, error)
    assert flat == pytest.approx([0.0, 0.0, 0.01, 0.05, 0.10])
    rows = {tuple(r["band_m"]): r for r in band_figures(distance, flat)}
    assert len(rows) == len(BANDS_M)
    assert rows[(4, 6)]["cells"] == 2 and rows[(4, 6)]["median_m"] == pytest.approx(0.03)
    assert rows[(4, 6)]["rms_m"] == pytest.approx(np.sqrt((0.01**2 + 0.05**2) / 2))
    assert rows[(4, 6)]["beyond_4cm_share"] == 0.5
    assert rows[(12, 15)]["median_m"] == pytest.approx(0.10) and rows[(15, 25)]["cells"] == 0
    assert rows[(15, 25)]["median_m"] is None


def test_a_terrain_falling_away_from_the_track_reads_as_negative_curvature() -> None:
    geo = RasterGeoreference(origin_xy=(0.0, 30.0), resolution=0.1, width=400, height=600)
    rows, _ = np.indices(geo.shape)
    y = 30.0 - 0.1 * rows
    elevation = (-0.002 * (y - 0.0) ** 2).astype(np.float32)  # a crest along y = 0: curvature -0.004 / m
    semantic = np.full(geo.shape, int(Semantic.ROAD), np.uint8)
    truth = BevRasters(geo, semantic=semantic, elevation=elevation)
    z, road = true_elevation(truth, np.array([[10.0, 5.0], [-50.0, 5.0]]))
    assert z[0] == pytest.approx(-0.05, abs=0.002) and road.tolist() == [True, False] and np.isnan(z[1])
    along_x = np.array(
        [[x, 0.0, 0.0] for x in (10.0, 20.0, 30.0)]
    )  # front cameras driving +x along the crest
    curvature = lateral_curvature(truth, along_x)
    for span in ("4_m", "8_m"):
        assert curvature[span]["median_per_m"] == pytest.approx(-0.004, rel=0.05)
        assert curvature[span]["negative_share"] == 1.0
