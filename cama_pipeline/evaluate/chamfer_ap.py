"""Chamfer-distance average precision as in MapTR: per class, per threshold, greedy matching by score.

Vectors are resampled to a fixed number of points; the Chamfer distance of two vectors is the mean of the
two directed mean nearest-point distances. For each class and threshold, predictions of all samples are
ranked by score; a prediction is a true positive when its nearest ground truth (same sample and class) is
within the threshold and not yet taken. AP is the area under the precision envelope (MapTR / mmdet `area`).
"""

import logging
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.distance import cdist

from annotations.geometry import resample_fixed
from annotations.schema import ELEMENT_CLASSES

logger = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class MapVector:
    """A map vector of one sample patch (ego frame metres); ground truth leaves `score` at 1."""

    cls: str
    points: np.ndarray
    """(N, 2) metres, N >= 2."""
    score: float = 1.0

    def __post_init__(self) -> None:
        if self.cls not in ELEMENT_CLASSES:
            raise ValueError(f"MapVector: unknown class {self.cls!r}, expected one of {ELEMENT_CLASSES}")
        points = np.asarray(self.points, dtype=np.float64)
        if points.ndim != 2 or points.shape[0] < 2 or points.shape[1] != 2 or not np.isfinite(points).all():
            raise ValueError(f"MapVector: points must be finite (N, 2) with N >= 2, got shape {points.shape}")
        if not np.isfinite(self.score):
            raise ValueError(f"MapVector: score must be finite, got {self.score}")
        object.__setattr__(self, "points", points)


@dataclass(frozen=True)
class ChamferApConfig:
    """MapTR's evaluation settings."""

    thresholds_m: tuple[float, ...] = (0.5, 1.0, 1.5)
    """Chamfer-distance thresholds."""
    num_points: int = 100
    """Points each vector is resampled to."""
    classes: tuple[str, ...] = ELEMENT_CLASSES
    """Classes evaluated (and averaged into mAP)."""

    def __post_init__(self) -> None:
        if not self.thresholds_m or any(not t > 0 for t in self.thresholds_m):
            raise ValueError(f"ChamferApConfig.thresholds_m must be positive, got {self.thresholds_m}")
        if self.num_points < 2:
            raise ValueError(f"ChamferApConfig.num_points must be >= 2, got {self.num_points}")
        unknown = set(self.classes) - set(ELEMENT_CLASSES)
        if not self.classes or unknown:
            raise ValueError(
                f"ChamferApConfig.classes: unknown {sorted(unknown)}, expected {ELEMENT_CLASSES}"
            )


@dataclass(frozen=True)
class ChamferApResult:
    """AP per class and threshold, per class (mean over thresholds) and mAP (mean over classes with ground truth)."""

    ap: dict[str, dict[float, float | None]]
    """ap[class][threshold]; None where the class has no ground truth."""
    class_ap: dict[str, float | None]
    mean_ap: float | None
    config: ChamferApConfig = field(default_factory=ChamferApConfig)


def chamfer_distance(a: np.ndarray, b: np.ndarray) -> float:
    """Mean of the two directed mean nearest-point distances between point sets a and b."""
    distances = cdist(a, b)
    return float((distances.min(axis=1).mean() + distances.min(axis=0).mean()) / 2)


def average_precision(tp: np.ndarray, num_gt: int) -> float:
    """Area under the precision envelope of score-ranked true/false positives (mmdet `area` mode)."""
    tp = np.asarray(tp, dtype=np.float64)
    tp_cum, fp_cum = np.cumsum(tp), np.cumsum(1 - tp)
    recall = tp_cum / num_gt
    precision = tp_cum / np.maximum(tp_cum + fp_cum, np.finfo(np.float64).eps)
    mrec = np.concatenate([[0.0], recall, [1.0]])
    mpre = np.concatenate([[0.0], precision, [0.0]])
    mpre = np.maximum.accumulate(mpre[::-1])[::-1]
    changes = np.flatnonzero(mrec[1:] != mrec[:-1])
    return float(((mrec[changes + 1] - mrec[changes]) * mpre[changes + 1]).sum())


def chamfer_ap(
    predictions: Mapping[str, Sequence[MapVector]],
    ground_truth: Mapping[str, Sequence[MapVector]],
    config: ChamferApConfig | None = None,
) -> ChamferApResult:
    """MapTR-style Chamfer AP of predictions against ground truth, both keyed by sample (patch) id."""
    config = config or ChamferApConfig()
    samples = sorted(set(predictions) | set(ground_truth))
    ap: dict[str, dict[float, float | None]] = {}
    for cls in config.classes:
        scores, distances, num_gt = _class_distances(
            predictions, ground_truth, samples, cls, config.num_points
        )
        ap[cls] = {t: _ap_at(scores, distances, num_gt, t) if num_gt else None for t in config.thresholds_m}
    class_ap = {c: _mean_defined(list(v.values())) for c, v in ap.items()}
    return ChamferApResult(ap, class_ap, _mean_defined(list(class_ap.values())), config)


def _class_distances(
    predictions: Mapping[str, Sequence[MapVector]],
    ground_truth: Mapping[str, Sequence[MapVector]],
    samples: list[str],
    cls: str,
    num_points: int,
) -> tuple[list[tuple[float, str, int]], dict[str, np.ndarray], int]:
    """Per-prediction (score, sample, index) and per-sample prediction x ground-truth Chamfer matrices."""
    scores: list[tuple[float, str, int]] = []
    distances: dict[str, np.ndarray] = {}
    num_gt = 0
    for sample in samples:
        preds = [resample_fixed(v.points, num_points) for v in predictions.get(sample, ()) if v.cls == cls]
        gts = [resample_fixed(v.points, num_points) for v in ground_truth.get(sample, ()) if v.cls == cls]
        pred_scores = [v.score for v in predictions.get(sample, ()) if v.cls == cls]
        num_gt += len(gts)
        distances[sample] = np.array([[chamfer_distance(p, g) for g in gts] for p in preds]).reshape(
            len(preds), len(gts)
        )
        scores.extend((s, sample, i) for i, s in enumerate(pred_scores))
    return scores, distances, num_gt


def _ap_at(
    scores: list[tuple[float, str, int]], distances: dict[str, np.ndarray], num_gt: int, threshold: float
) -> float:
    """AP at one threshold: greedy matching in descending score order."""
    order = sorted(range(len(scores)), key=lambda k: -scores[k][0])
    taken = {sample: np.zeros(d.shape[1], bool) for sample, d in distances.items()}
    tp = np.zeros(len(order))
    for rank, k in enumerate(order):
        _, sample, index = scores[k]
        row = distances[sample][index]
        if row.size and row.min() <= threshold and not taken[sample][row.argmin()]:
            taken[sample][row.argmin()] = True
            tp[rank] = 1
    return average_precision(tp, num_gt) if len(order) else 0.0


def _mean_defined(values: list[float | None]) -> float | None:
    """Mean of the values that are not None; None when none is."""
    defined = [v for v in values if v is not None]
    return float(np.mean(defined)) if defined else None
