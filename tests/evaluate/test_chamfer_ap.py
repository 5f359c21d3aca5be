"""MapTR-style Chamfer-AP on hand-made predictions with known answers."""

import numpy as np
import pytest

from annotations.geometry import resample_fixed
from cama_pipeline.evaluate.chamfer_ap import (
    ChamferApConfig,
    MapVector,
    average_precision,
    chamfer_ap,
    chamfer_distance,
)


def line(y: float, cls: str = "divider", score: float = 1.0) -> MapVector:
    """A 20 m straight vector along x at lateral offset y."""
    return MapVector(cls, np.array([[-10.0, y], [0.0, y], [10.0, y]]), score)


GROUND_TRUTH = {
    "s1": [line(0.0), line(3.5), line(-6.0, "boundary")],
    "s2": [line(1.0), MapVector("ped_crossing", np.array([[0, 0], [4, 0], [4, 3], [0, 3], [0, 0]], float))],
}


def test_resample_and_chamfer_distance() -> None:
    points = resample_fixed(np.array([[0.0, 0.0], [10.0, 0.0]]), 11)
    assert np.allclose(points[:, 0], np.arange(11))
    assert chamfer_distance(points, points + [0.0, 0.8]) == pytest.approx(0.8)


def test_perfect_predictions_give_ap_one() -> None:
    result = chamfer_ap(GROUND_TRUTH, GROUND_TRUTH)
    assert result.mean_ap == pytest.approx(1.0)
    assert all(v == pytest.approx(1.0) for per_class in result.ap.values() for v in per_class.values())


def test_offset_counts_only_at_looser_thresholds() -> None:
    predictions = {"s1": [line(0.8)]}
    ground_truth = {"s1": [line(0.0)]}
    ap = chamfer_ap(predictions, ground_truth, ChamferApConfig(classes=("divider",))).ap["divider"]
    assert ap == {0.5: 0.0, 1.0: pytest.approx(1.0), 1.5: pytest.approx(1.0)}


def test_high_scoring_false_positive_lowers_ap() -> None:
    ground_truth = {"s1": [line(0.0)]}
    clean = chamfer_ap({"s1": [line(0.0, score=0.9)]}, ground_truth).class_ap["divider"]
    noisy = chamfer_ap({"s1": [line(0.0, score=0.5), line(20.0, score=0.95)]}, ground_truth).class_ap[
        "divider"
    ]
    low_fp = chamfer_ap({"s1": [line(0.0, score=0.9), line(20.0, score=0.1)]}, ground_truth).class_ap[
        "divider"
    ]
    assert clean == pytest.approx(1.0)
    assert noisy == pytest.approx(0.5)
    assert low_fp == pytest.approx(1.0)


def test_duplicate_prediction_is_a_false_positive() -> None:
    result = chamfer_ap({"s1": [line(0.0, score=0.9), line(0.1, score=0.8)]}, {"s1": [line(0.0)]})
    assert result.ap["divider"][0.5] == pytest.approx(1.0)  # the duplicate ranks after the only true positive
    assert average_precision(np.array([0.0, 1.0]), 1) == pytest.approx(0.5)


def test_classes_without_ground_truth_are_left_out_of_the_mean() -> None:
    result = chamfer_ap({"s1": [line(0.0)]}, {"s1": [line(0.0)]})
    assert result.class_ap["boundary"] is None and result.mean_ap == pytest.approx(1.0)


def test_missed_ground_truth_lowers_recall() -> None:
    result = chamfer_ap({"s1": [line(0.0)]}, {"s1": [line(0.0), line(3.5)]})
    assert result.class_ap["divider"] == pytest.approx(0.5)


@pytest.mark.parametrize(
    "make, message",
    [
        (lambda: MapVector("lane", np.zeros((2, 2))), "unknown class"),
        (lambda: MapVector("divider", np.zeros((1, 2))), "N >= 2"),
        (lambda: MapVector("divider", np.array([[0.0, 0.0], [np.nan, 1.0]])), "finite"),
        (lambda: ChamferApConfig(thresholds_m=(0.0,)), "thresholds_m"),
        (lambda: ChamferApConfig(classes=("lane",)), "unknown"),
    ],
)
def test_bad_inputs_raise(make, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        make()
