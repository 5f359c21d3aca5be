"""Where a segmenter's thin classes lose their IoU: on the true region's one-pixel edge, or beyond it.

Lane markings, kerbs and crosswalk stripes are a few pixels wide in a 512x288 image, so a mask that is right but
one pixel too fat or too thin on each side already has an IoU near 0.5. This split tells that case (a boundary
bias, which a logit offset or sharper training labels can fix) from missed or invented pieces (which need a
better network). Every pixel of a class's IoU union is one of: `hit` (true and predicted), `missed_on_edge` (a
true pixel not predicted, on the true region's edge: a 4-neighbour is not of the class), `missed_inside` (the
rest of the missed), `extra_on_edge` (predicted, not true, but a 4-neighbour of a true pixel), `extra_beyond`
(the rest of the predicted but not true). `iou_edge_tolerant` forgives the two edge kinds.
"""

from collections.abc import Sequence
from typing import Any

import numpy as np
from scipy import ndimage

from cama_pipeline.semantics import Semantic

THIN_CLASSES = (Semantic.CURB, Semantic.LANE_MARKING, Semantic.CROSSWALK)
KINDS = ("hit", "missed_on_edge", "missed_inside", "extra_on_edge", "extra_beyond")


class EdgeErrors:
    """Pixel counts of `KINDS` per class, summed over the images `add` is given."""

    def __init__(self, classes: Sequence[Semantic] = THIN_CLASSES) -> None:
        self.classes = tuple(classes)
        self.counts = {c: dict.fromkeys(KINDS, 0) for c in self.classes}
        self.predicted = dict.fromkeys(self.classes, 0)
        self.true = dict.fromkeys(self.classes, 0)

    def add(self, predicted: np.ndarray, truth: np.ndarray) -> None:
        """Count one image's (H, W) predicted and true class ids."""
        if predicted.shape != truth.shape:
            raise ValueError(f"prediction {predicted.shape} and truth {truth.shape} differ in size")
        for cls in self.classes:
            true, hit = truth == int(cls), predicted == int(cls)
            edge = true & ~ndimage.binary_erosion(true, border_value=1)
            touching = ndimage.binary_dilation(true) & ~true
            counts = self.counts[cls]
            counts["hit"] += int((true & hit).sum())
            counts["missed_on_edge"] += int((true & ~hit & edge).sum())
            counts["missed_inside"] += int((true & ~hit & ~edge).sum())
            counts["extra_on_edge"] += int((hit & touching).sum())
            counts["extra_beyond"] += int((hit & ~true & ~touching).sum())
            self.predicted[cls] += int(hit.sum())
            self.true[cls] += int(true.sum())

    def report(self) -> dict[str, dict[str, Any]]:
        """Per class name: each kind's share of the union, the IoU, the IoU with edge errors forgiven, and the
        predicted area over the true area (above 1: the class is drawn too fat). None where the class is absent."""
        out: dict[str, dict[str, Any]] = {}
        for cls, counts in self.counts.items():
            union = sum(counts.values())
            if union == 0:
                out[cls.name.lower()] = {"union_pixels": 0}
                continue
            forgiven = union - counts["missed_on_edge"] - counts["extra_on_edge"]
            out[cls.name.lower()] = {
                "union_pixels": union,
                **{kind: round(n / union, 4) for kind, n in counts.items()},
                "iou": round(counts["hit"] / union, 4),
                "iou_edge_tolerant": round(counts["hit"] / forgiven, 4) if forgiven else None,
                "predicted_over_true": round(self.predicted[cls] / self.true[cls], 3)
                if self.true[cls]
                else None,
            }
        return out
