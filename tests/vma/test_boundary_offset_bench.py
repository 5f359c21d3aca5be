"""`bench/boundary_offset.py` measures how far proposed boundaries and the raster's road edge lie on the road's side
of the true kerbs (its refusal of a seen checkpoint: `test_boundary_evidence_bench`)."""

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from app.review_effort.plan import Polyline
from bench.boundary_offset import offset_figures, station_offsets
from cama_pipeline.semantics import Semantic
from models.vma.rasters import load_site_rasters
from models.vma.vectors import Vector
from tests.vma.vma_test_sites import global_xy


def along_x(y_m: float) -> np.ndarray:
    return np.array([global_xy(5.0, y_m), global_xy(55.0, y_m)])


def test_offsets_are_measured_on_the_road_side_of_each_true_kerb(drawn_site: Path) -> None:
    rasters = load_site_rasters(drawn_site)
    semantic = np.full(rasters.shape, int(Semantic.BACKGROUND), np.uint8)
    # the road's run ends at y = 19.75 m, a quarter metre short of the kerb
    semantic[:198] = int(Semantic.ROAD)
    rasters = replace(rasters, semantic=semantic)
    truths = [Polyline("boundary", along_x(20.0)), Polyline("divider", along_x(10.0))]
    proposals = [
        Vector("boundary", along_x(19.9), 0.9),  # 0.1 m on the road's side
        Vector("boundary", along_x(20.0), 0.01),  # under the review's confidence floor: not the kerb's line
        Vector("divider", along_x(10.0), 0.9),
    ]
    rows = station_offsets(rasters, proposals, truths)
    assert len(rows) == 50  # a station a metre along the 50 m kerb; the divider has none
    assert all(proposal == pytest.approx(0.1) for proposal, _ in rows)
    assert all(edge == pytest.approx(0.3, abs=0.06) for _, edge in rows)
    figures = offset_figures(rows)
    assert figures["stations"] == 50 and figures["proposal_median_roadward_m"] == pytest.approx(0.1)
    assert figures["road_edge_median_roadward_m"] == pytest.approx(0.3, abs=0.06)
    assert figures["proposal_beyond_0_2_m_share"] == 0.0
    far = [Vector("boundary", along_x(18.5), 0.9)]  # 1.5 m inside the road: another line, not this kerb's
    assert station_offsets(rasters, far, truths) == []
