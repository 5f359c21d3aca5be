"""`bench/paint_placement.py` reads where the rasters show a line's paint: at its offset across the true line, and
nowhere where the rasters have none."""

import numpy as np
import pytest
from shapely.geometry import LineString

from bench.paint_placement import lane_marking, paint_offsets, stations_along
from cama_pipeline.bev import RasterGeoreference
from cama_pipeline.semantics import Semantic
from models.vma.rasters import SiteRasters


def test_paint_beside_the_true_line_is_read_at_its_offset() -> None:
    geo = RasterGeoreference(origin_xy=(0.0, 20.0), resolution=0.1, width=200, height=200)
    semantic = np.full(geo.shape, int(Semantic.ROAD), np.uint8)
    rows = np.arange(geo.height)
    y = 20.0 - 0.1 * rows  # rows run towards -y
    painted = np.abs(y - 10.3) <= 0.075  # a 0.15 m line 0.3 m left of the true line y = 10 (driving +x)
    semantic[np.ix_(painted, np.arange(0, 120))] = int(Semantic.LANE_MARKING)  # paint up to x = 12 m only
    rasters = SiteRasters(semantic, np.zeros((*geo.shape, 3), np.uint8), geo)
    offsets = paint_offsets(
        rasters, lane_marking(rasters), *stations_along(LineString([(2.0, 10.0), (18.0, 10.0)]))
    )
    stations = 2.0 + np.arange(0.25, 16.0, 0.5)
    assert len(offsets) == len(stations)
    assert offsets[stations < 11.9] == pytest.approx(0.3, abs=0.03)
    assert np.isnan(offsets[stations > 12.1]).all()
    reversed_offsets = paint_offsets(
        rasters, lane_marking(rasters), *stations_along(LineString([(18.0, 10.0), (2.0, 10.0)]))
    )
    assert np.nanmedian(reversed_offsets) == pytest.approx(-0.3, abs=0.03)  # across is to the line's left
