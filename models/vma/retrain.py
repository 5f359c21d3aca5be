"""Retraining from people's corrections, behind an evaluation gate: the function the backend's job calls.

Accepted, fixed and approved annotations are labels; rejected proposals are negatives (patches are cut
around them too, where the labels say nothing is there). The promoted checkpoint is fine-tuned on patches
around corrected elements mixed with procedural patches (against forgetting), then both it and the candidate
are evaluated with Chamfer-AP on held-out validation sites; the candidate is saved as a new version with
its metrics and data either way, and promoted only if its mAP does not drop (by more than `tolerance`).
A caller may give a second gate, `review` (the backend's job gives the simulated annotator's time,
`app.review_effort.review_time`, which this layer cannot import): it scores each model's proposer on the same
sites, and the candidate is promoted only if the annotator's correction time does not grow (by more than
`time_tolerance`, a share) either.

Patches are cut wherever corrections are; unreviewed elements inside such a patch count as background,
so correction batches should cover whole regions (the lead view retrains after regions are reviewed).
An anchored model's patches carry the rule-based candidates of the corrected site as anchors. Each saved
candidate records the pre-accept threshold calibrated on its validation proposals (`models.vma.loop`).
"""

import logging
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from annotations import AnnotationSet
from models.vma.checkpoint import (
    ensure_unseen,
    load_checkpoint,
    promote,
    refuse_seen_validation,
    round_to_stored,
    save_version,
    seen_records,
)
from models.vma.config import ModelConfig, TrainConfig, config_dict
from models.vma.evaluate import evaluate_proposer
from models.vma.gate import TIME_CONFIDENCE, check_time_confidence, gate_passes
from models.vma.infer import InferenceConfig, predict_site
from models.vma.loop import THRESHOLD_KEY
from models.vma.model import VmaNet
from models.vma.patches import Sample, SiteGrid, degrade, procedural_sample, site_grid, site_sample
from models.vma.rasters import SiteRasters, load_site_rasters
from models.vma.rule_based import propose_rule_based
from models.vma.train import Sampler, fit
from models.vma.validation import ValidationEntry
from models.vma.vectors import Vector, vectors_from_annotations

logger = logging.getLogger(__name__)

LABEL_STATES = ("accepted", "fixed", "approved")
NEGATIVE_STATES = ("rejected",)


@dataclass(frozen=True)
class Corrections:
    """Reviewed annotations of one site and where its rasters are."""

    site: Path
    """Site folder (rasters in it or in ground_truth/bev/)."""
    annotations: AnnotationSet


@dataclass(frozen=True)
class RetrainConfig:
    """Fine-tuning and gate settings."""

    train: TrainConfig = field(default_factory=lambda: TrainConfig(steps=300, learning_rate=2e-4))
    replay_share: float = 0.3
    """Share of procedural patches in each fine-tuning batch."""
    tolerance: float = 0.0
    """The candidate is promoted when its mAP >= current mAP - tolerance."""
    min_labels: int = 1
    """Fewer labelled elements than this: nothing to learn from, a ValueError."""
    inference: InferenceConfig = field(default_factory=InferenceConfig)
    time_tolerance: float = 0.0
    """With a `review` gate: promoted only when its correction time <= current time * (1 + time_tolerance)."""
    time_confidence: float = TIME_CONFIDENCE
    """... and, with each site's time, only when it saves time in at least this share of bootstrap resamples of
    the validation sites (`saving_confidence`; 0: the totals alone decide)."""

    def __post_init__(self) -> None:
        if not 0.0 <= self.replay_share < 1.0 or self.tolerance < 0 or self.min_labels < 1:
            raise ValueError(
                "RetrainConfig: replay_share in [0, 1), tolerance >= 0, min_labels >= 1 required"
            )
        if self.time_tolerance < 0:
            raise ValueError(f"RetrainConfig: time_tolerance must be >= 0, got {self.time_tolerance}")
        check_time_confidence(self.time_confidence, "RetrainConfig")


Proposer = Callable[[SiteRasters], list[Vector]]
ReviewGate = Callable[[Proposer, Sequence[ValidationEntry]], dict[str, Any]]
"""Scores a proposer on validation sites by review effort: {"correction_s": seconds, ...} at least."""


@dataclass(frozen=True)
class RetrainResult:
    """What a retraining run did."""

    candidate: Path
    """The new checkpoint version folder."""
    promoted: bool
    current_metrics: dict[str, Any]
    candidate_metrics: dict[str, Any]
    labels: int
    negatives: int


@dataclass(frozen=True, eq=False)
class PreparedCorrections:
    """One corrected site ready for patch sampling."""

    grid: SiteGrid
    labels: list[Vector]
    negatives: list[Vector]
    candidates: list[Vector] | None
    """The site's rule-based candidates (anchored models only)."""


def correction_sampler(
    corrections: Sequence[PreparedCorrections], config: ModelConfig, replay_share: float
) -> Sampler:
    """Patches centred on a random labelled or rejected element (random point along it, any rotation)."""

    def draw(rng: np.random.Generator) -> Sample:
        if rng.random() < replay_share:
            return procedural_sample(config, rng)
        item = corrections[int(rng.integers(len(corrections)))]
        elements = item.labels + item.negatives
        element = elements[int(rng.integers(len(elements)))]
        point = element.points[int(rng.integers(len(element.points)))] + rng.normal(0, 4.0, 2)
        centre = item.grid.pixel_from_global(point)[0]
        angle = float(rng.uniform(0, 2 * np.pi))
        sample = site_sample(item.grid, item.labels, config, centre, angle, item.candidates)
        if sample.anchors is not None:
            return sample
        return degrade(sample, rng) if rng.random() < 0.5 else sample

    return draw


def model_proposer(model: VmaNet, inference: InferenceConfig) -> Proposer:
    """A site's proposals by `model`."""
    return lambda rasters: predict_site(model, rasters, inference, show_progress=False)


def evaluate_model(
    model: VmaNet,
    sites: Sequence[ValidationEntry],
    inference: InferenceConfig,
    review: ReviewGate | None = None,
) -> dict[str, Any]:
    """Chamfer-AP of a model's site proposals on validation sites, and their `review` figures (key "review")
    when a review gate is given."""
    metrics = evaluate_proposer(model_proposer(model, inference), sites)
    if review is not None:
        metrics["review"] = review(model_proposer(model, inference), sites)
    return metrics


def retrain_from_corrections(
    registry: Path,
    corrections: Sequence[Corrections],
    validation_sites: Sequence[ValidationEntry],
    config: RetrainConfig | None = None,
    *,
    review: ReviewGate | None = None,
    show_progress: bool = False,
) -> RetrainResult:
    """Fine-tune the promoted model of `registry` on corrections; save the candidate; promote it if the gates
    pass (mAP, and `review` when given)."""
    config = config or RetrainConfig()
    started = time.perf_counter()
    current = load_checkpoint(Path(registry))
    seen = seen_records([c.site for c in corrections], current)
    refuse_seen_validation(seen, validation_sites, f"{current.path} with these corrections")
    prepared = []
    for item in corrections:
        labels = vectors_from_annotations(item.annotations, LABEL_STATES)
        negatives = [v for v in vectors_from_annotations(item.annotations, NEGATIVE_STATES)]
        if labels or negatives:
            rasters = load_site_rasters(item.site)
            candidates = propose_rule_based(rasters) if current.config.anchored else None
            prepared.append(
                PreparedCorrections(site_grid(rasters, current.config), labels, negatives, candidates)
            )
    num_labels = sum(len(p.labels) for p in prepared)
    num_negatives = sum(len(p.negatives) for p in prepared)
    if num_labels < config.min_labels:
        raise ValueError(
            f"retrain: {num_labels} accepted/fixed annotations, need at least {config.min_labels}"
        )
    current_metrics = evaluate_model(current.model, validation_sites, config.inference, review)
    candidate = load_checkpoint(current.path).model  # a fresh copy to fine-tune
    fit(
        candidate,
        correction_sampler(prepared, current.config, config.replay_share),
        config.train,
        show_progress=show_progress,
    )
    round_to_stored(candidate.cpu())
    candidate_metrics = evaluate_model(candidate, validation_sites, config.inference, review)
    promoted = gate_passes(current_metrics, candidate_metrics, config)
    return save_candidate(
        Path(registry),
        candidate,
        CandidateRecord(
            current.path.name,
            config_dict(config.train),
            corrections,
            validation_sites,
            seen,
            (num_labels, num_negatives),
            time.perf_counter() - started,
        ),
        current_metrics,
        candidate_metrics,
        promoted,
        {THRESHOLD_KEY: candidate_metrics.get(THRESHOLD_KEY)},
    )


@dataclass(frozen=True)
class CandidateRecord:
    """What a retrained candidate's `checkpoint.json` says it came from."""

    parent: str
    """The version it was fine-tuned from."""
    train_config: dict[str, Any]
    corrections: Sequence[Corrections]
    validation_sites: Sequence[ValidationEntry]
    seen: dict[str, list[Any]]
    """`seen_records` of the parent and the corrected sites."""
    counts: tuple[int, int]
    """Labels and negatives it learned from."""
    seconds: float


def save_candidate(
    registry: Path,
    candidate: torch.nn.Module,
    record: CandidateRecord,
    current_metrics: dict[str, Any],
    candidate_metrics: dict[str, Any],
    promoted: bool,
    extra_meta: dict[str, Any],
) -> RetrainResult:
    """Save a retrained candidate as the next version of `registry` with its figures and data (and
    `extra_meta`), promote it when the gates passed, and say so in the log."""
    labels, negatives = record.counts
    meta = {
        "parent": record.parent,
        "train_config": record.train_config,
        "metrics": {
            "validation": candidate_metrics,
            "parent_validation": current_metrics,
            "seconds": round(record.seconds, 1),
        },
        "data": {
            "corrections": [
                {
                    "site": str(c.site),
                    "site_id": c.annotations.site_id,
                    "elements": len(c.annotations.elements),
                }
                for c in record.corrections
            ],
            "labels": labels,
            "negatives": negatives,
            "validation_sites": [str(s) for s in record.validation_sites],
            **record.seen,
        },
        "promoted": promoted,
        **extra_meta,
    }
    folder = save_version(registry, candidate, meta)
    if promoted:
        promote(registry, folder.name)
    logger.info(
        "retrain: candidate %s mAP %s vs current %s -> %s",
        folder.name,
        candidate_metrics["mean_ap"],
        current_metrics["mean_ap"],
        "promoted" if promoted else "kept out",
    )
    return RetrainResult(folder, promoted, current_metrics, candidate_metrics, labels, negatives)


def gate_checkpoint(
    registry: Path,
    candidate: Path,
    validation_sites: Sequence[Path],
    config: RetrainConfig | None = None,
    *,
    allow_new_config: bool = False,
    review: ReviewGate | None = None,
) -> tuple[bool, dict[str, Any], dict[str, Any]]:
    """Evaluate a candidate version of `registry` against the promoted one; promote it if the gate passes.

    Returns (promoted, current metrics, candidate metrics). A candidate for another model config is refused
    with a CheckpointError before any evaluation, unless `allow_new_config` (a newly trained architecture
    competing with the promoted one on the same validation sites). `review`: the second gate, as in
    `retrain_from_corrections`.
    """
    config = config or RetrainConfig()
    current = load_checkpoint(Path(registry))
    challenger = load_checkpoint(Path(candidate), None if allow_new_config else current.config)
    for site in validation_sites:
        ensure_unseen(current, Path(site))
        ensure_unseen(challenger, Path(site))
    current_metrics = evaluate_model(current.model, validation_sites, config.inference, review)
    candidate_metrics = evaluate_model(challenger.model, validation_sites, config.inference, review)
    promoted = gate_passes(current_metrics, candidate_metrics, config)
    if promoted:
        promote(Path(registry), challenger.path.name)
    logger.info(
        "gate: %s mAP %s vs current %s -> %s",
        challenger.path.name,
        candidate_metrics["mean_ap"],
        current_metrics["mean_ap"],
        promoted,
    )
    return promoted, current_metrics, candidate_metrics
