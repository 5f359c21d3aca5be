"""Chamfer-AP of site-wide proposals against ground truth, tile by tile as MapTR evaluates ego patches.

The site is cut into square evaluation tiles; predictions and ground truth are both clipped to each tile
(pieces shorter than `min_length_m` dropped) and each tile is one sample of `cama_pipeline.evaluate.chamfer_ap`.
The confidence report bins predictions by score and gives the precision per bin (a prediction is correct
when a same-class ground truth of its tile lies within the threshold), so one can see whether confidence
ranks errors; from the same outcomes the pre-accept threshold of the loop is calibrated
(`models.vma.loop.calibrate_preaccept_threshold`).
"""

import logging
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from annotations.geometry import resample_fixed
from cama_pipeline.evaluate.chamfer_ap import (
    ChamferApConfig,
    ChamferApResult,
    MapVector,
    chamfer_ap,
    chamfer_distance,
)
from models.vma.loop import LoopConfig, calibrate_preaccept_threshold
from models.vma.rasters import SiteRasters, load_site_rasters
from models.vma.validation import ValidationEntry, as_validation_site, true_vectors
from models.vma.vectors import Vector, clip_vectors

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class SiteEvalConfig:
    """How a site is tiled for Chamfer-AP."""

    tile_m: float = 30.0
    """Side of the square evaluation tiles."""
    min_length_m: float = 1.0
    """Clipped pieces shorter than this are ignored (in predictions and ground truth alike)."""
    confidence_bins: tuple[float, ...] = (0.0, 0.25, 0.5, 0.75, 1.0001)
    """Edges of the confidence bins of the precision report."""
    bin_threshold_m: float = 1.0
    """Chamfer threshold of the per-bin precision (and of the pre-accept calibration)."""
    loop: LoopConfig = LoopConfig()
    """Target precision of the calibrated pre-accept threshold."""

    def __post_init__(self) -> None:
        if self.tile_m <= 0 or self.min_length_m < 0 or self.bin_threshold_m <= 0:
            raise ValueError("SiteEvalConfig: tile_m and bin_threshold_m must be > 0, min_length_m >= 0")
        if len(self.confidence_bins) < 2 or list(self.confidence_bins) != sorted(self.confidence_bins):
            raise ValueError(
                f"SiteEvalConfig.confidence_bins must be increasing edges, got {self.confidence_bins}"
            )


def tile_samples(
    vectors: Sequence[Vector],
    bounds: tuple[float, float, float, float],
    config: SiteEvalConfig,
    prefix: str = "",
) -> dict[str, list[MapVector]]:
    """Vectors clipped to each evaluation tile of `bounds` (xmin, xmax, ymin, ymax), keyed `<prefix>tile-i-j`."""
    xmin, xmax, ymin, ymax = bounds
    samples: dict[str, list[MapVector]] = {}
    for i, x0 in enumerate(np.arange(xmin, xmax, config.tile_m)):
        for j, y0 in enumerate(np.arange(ymin, ymax, config.tile_m)):
            tile = (float(x0), float(x0 + config.tile_m), float(y0), float(y0 + config.tile_m))
            samples[f"{prefix}tile-{i}-{j}"] = [
                v.to_map_vector() for v in clip_vectors(vectors, tile, config.min_length_m)
            ]
    return samples


def evaluate_sites(
    sites: Sequence[tuple[Sequence[Vector], Sequence[Vector], tuple[float, float, float, float]]],
    config: SiteEvalConfig | None = None,
) -> dict:
    """Chamfer-AP and the per-confidence-bin precision over sites given as (predictions, truth, bounds)."""
    config = config or SiteEvalConfig()
    predictions: dict[str, list[MapVector]] = {}
    truth: dict[str, list[MapVector]] = {}
    for k, (pred, gt, bounds) in enumerate(sites):
        predictions.update(tile_samples(pred, bounds, config, prefix=f"s{k}-"))
        truth.update(tile_samples(gt, bounds, config, prefix=f"s{k}-"))
    result = chamfer_ap(predictions, truth)
    scores, correct = prediction_outcomes(predictions, truth, config)
    return {
        **ap_json(result),
        "confidence_bins": confidence_bins(scores, correct, config),
        "preaccept_threshold": calibrate_preaccept_threshold(scores, correct, config.loop),
    }


def ap_json(result: ChamferApResult) -> dict:
    """Chamfer-AP as plain JSON: per class and threshold, per class, and mean."""
    return {
        "ap": {cls: {str(t): v for t, v in per.items()} for cls, per in result.ap.items()},
        "class_ap": result.class_ap,
        "mean_ap": result.mean_ap,
    }


def prediction_outcomes(
    predictions: dict[str, list[MapVector]], truth: dict[str, list[MapVector]], config: SiteEvalConfig
) -> tuple[np.ndarray, np.ndarray]:
    """Score of every prediction and whether a same-class truth of its tile lies within `bin_threshold_m`."""
    num_points = ChamferApConfig().num_points
    scores, correct = [], []
    for sample, preds in predictions.items():
        gts = truth.get(sample, [])
        for pred in preds:
            same = [resample_fixed(g.points, num_points) for g in gts if g.cls == pred.cls]
            p = resample_fixed(pred.points, num_points)
            best = min((chamfer_distance(p, g) for g in same), default=np.inf)
            scores.append(pred.score)
            correct.append(best <= config.bin_threshold_m)
    return np.asarray(scores, np.float64), np.asarray(correct, bool)


def confidence_bins(scores_a: np.ndarray, correct_a: np.ndarray, config: SiteEvalConfig) -> list[dict]:
    """Per confidence bin: how many predictions, how many correct, and precision."""
    out = []
    edges = config.confidence_bins
    for lo, hi in zip(edges[:-1], edges[1:], strict=True):
        inside = (scores_a >= lo) & (scores_a < hi)
        n = int(inside.sum())
        out.append(
            {
                "low": lo,
                "high": min(hi, 1.0),
                "count": n,
                "correct": int(correct_a[inside].sum()),
                "precision": float(correct_a[inside].mean()) if n else None,
            }
        )
    return out


def evaluate_proposer(
    propose: Callable[[SiteRasters], list[Vector]],
    sites: Sequence[ValidationEntry],
    config: SiteEvalConfig | None = None,
) -> dict:
    """Chamfer-AP (+ confidence bins, vector counts, seconds per km²) of a proposer on sites with ground truth
    (a path: its own rasters; a `ValidationSite`: its rasters, a reconstruction's against the observed truth)."""
    if not sites:
        raise ValueError("evaluate: no validation sites given")
    triples = []
    seconds, area = 0.0, 0.0
    for entry in sites:
        site = as_validation_site(entry)
        rasters = load_site_rasters(site.rasters)
        truth = true_vectors(site, rasters)
        started = time.perf_counter()
        predictions = propose(rasters)
        seconds += time.perf_counter() - started
        area += rasters.area_km2()
        triples.append((predictions, truth, rasters.extent()))
    result = evaluate_sites(triples, config)
    result["sites"] = [str(s) for s in sites]
    result["num_predictions"] = sum(len(p) for p, _, _ in triples)
    result["num_ground_truth"] = sum(len(g) for _, g, _ in triples)
    result["seconds_per_km2"] = seconds / area if area > 0 else None
    return result
