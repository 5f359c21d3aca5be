"""The split of the thin classes' IoU into edge and beyond-edge errors (`cama_pipeline.segment.edge_errors`)."""

import numpy as np
import pytest

from cama_pipeline.segment.edge_errors import EdgeErrors
from cama_pipeline.semantics import Semantic

MARKING = int(Semantic.LANE_MARKING)
ROAD = int(Semantic.ROAD)


def _stripe(columns: slice) -> np.ndarray:
    mask = np.full((20, 30), ROAD, np.uint8)
    mask[:, columns] = MARKING
    return mask


def test_a_mask_one_pixel_too_fat_loses_only_on_the_edge() -> None:
    errors = EdgeErrors()
    errors.add(_stripe(slice(10, 15)), _stripe(slice(11, 14)))
    marking = errors.report()["lane_marking"]
    assert marking["iou"] == pytest.approx(3 / 5)
    assert marking["extra_on_edge"] == pytest.approx(2 / 5)
    assert marking["extra_beyond"] == marking["missed_on_edge"] == marking["missed_inside"] == 0
    assert marking["iou_edge_tolerant"] == 1.0
    assert marking["predicted_over_true"] == pytest.approx(5 / 3, abs=1e-3)


def test_a_missed_stripe_and_an_invented_one_are_not_forgiven() -> None:
    truth = _stripe(slice(2, 7))
    predicted = _stripe(slice(20, 23))
    errors = EdgeErrors()
    errors.add(predicted, truth)
    marking = errors.report()["lane_marking"]
    # 5 true columns: the outer 2 are edge, the inner 3 inside; 3 invented columns far from any true pixel
    assert marking["missed_on_edge"] == pytest.approx(2 / 8)
    assert marking["missed_inside"] == pytest.approx(3 / 8)
    assert marking["extra_beyond"] == pytest.approx(3 / 8)
    assert marking["iou"] == marking["iou_edge_tolerant"] == 0.0


def test_the_image_border_is_not_an_edge_and_absent_classes_are_reported_empty() -> None:
    truth = np.full((8, 8), MARKING, np.uint8)
    predicted = truth.copy()
    predicted[3:5, 3:5] = ROAD
    errors = EdgeErrors()
    errors.add(predicted, truth)
    report = errors.report()
    assert report["lane_marking"]["missed_inside"] == pytest.approx(4 / 64)
    assert report["lane_marking"]["missed_on_edge"] == 0
    assert report["curb"] == {"union_pixels": 0}


def test_masks_of_different_sizes_are_refused() -> None:
    with pytest.raises(ValueError, match="differ in size"):
        EdgeErrors().add(np.zeros((4, 5), np.uint8), np.zeros((5, 4), np.uint8))
