"""`bench/crossing_fit.py` scores each proposed crossing against the true crossing it overlaps most."""

import numpy as np
import pytest

from app.review_effort.plan import Polyline, SimulationConfig
from bench.crossing_fit import crossing_errors
from models.vma.vectors import Vector


def ring(x0: float, y0: float, width: float, length: float) -> np.ndarray:
    corners = [[x0, y0], [x0 + width, y0], [x0 + width, y0 + length], [x0, y0 + length]]
    return np.array([*corners, corners[0]], dtype=np.float64)


def test_each_crossing_is_scored_against_the_truth_it_overlaps_most() -> None:
    truths = [Polyline("ped_crossing", ring(0, 0, 4, 15)), Polyline("ped_crossing", ring(40, 0, 4, 15))]
    proposals = [
        Vector("ped_crossing", ring(40.05, 0.05, 4, 15), 0.9),  # on the second, within the acceptance
        Vector("ped_crossing", ring(-0.5, 0, 5, 15), 0.9),  # the first, half a metre too wide
        Vector("ped_crossing", ring(100, 0, 4, 15), 0.9),  # overlaps nothing: left out
        Vector("ped_crossing", ring(0, 0, 4, 15), 0.01),  # under the review's confidence floor
        Vector("divider", np.array([[0.0, 0.0], [10.0, 0.0]]), 0.9),
    ]
    rows = crossing_errors(proposals, truths, SimulationConfig())
    assert len(rows) == 2
    assert rows[0]["acceptable"] and rows[0]["iou"] == pytest.approx(0.963, abs=0.01)
    assert not rows[1]["acceptable"] and rows[1]["iou"] == pytest.approx(0.8)
