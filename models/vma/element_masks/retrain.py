"""Retraining the element-mask network from people's corrections, behind the same gates as the MapTR-style model.

Accepted, fixed and approved elements of each corrected site are drawn as the target masks (`targets`), so a
fixed line teaches the network where the line really is; rejected proposals are negatives: crops are cut around
them too, where the targets say nothing is there. Crops are centred on labelled and rejected elements (unreviewed
elements inside a crop count as background, so correction batches should cover whole regions, as for the
MapTR-style model). The promoted version is fine-tuned at a low rate on the corrected sites' clean and damaged
rasters, optionally with `replay_share` of the crops cut from a few of its own generator training sites
(`replay`, rehearsal against forgetting what the first model knew); candidate and current are scored on
held-out validation sites (Chamfer-AP, and the `review` gate's annotator time when given); the candidate is
saved either way with what it saw and promoted only if both gates pass (`models.vma.gate.gate_passes`).
"""

import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from models.vma.checkpoint import META, CheckpointError, refuse_seen_validation, round_to_stored, seen_records
from models.vma.config import config_dict
from models.vma.element_masks.checkpoint import KIND, MaskCheckpoint, load_mask_checkpoint
from models.vma.element_masks.config import MaskTrainConfig
from models.vma.element_masks.net import ElementMaskNet
from models.vma.element_masks.propose import product_proposer
from models.vma.element_masks.replay import rehearsed_reconstructions, replay_sites
from models.vma.element_masks.train import fit_masks, training_site
from models.vma.evaluate import evaluate_proposer
from models.vma.gate import TIME_CONFIDENCE, check_time_confidence, gate_passes
from models.vma.rasters import load_site_rasters
from models.vma.retrain import (
    LABEL_STATES,
    NEGATIVE_STATES,
    CandidateRecord,
    Corrections,
    RetrainResult,
    ReviewGate,
    save_candidate,
)
from models.vma.train import DAMAGE_SEED_BASE
from models.vma.validation import ValidationEntry
from models.vma.vectors import vectors_from_annotations

REPLAY_FOLDER = "replay-sites"
"""The registry's cache of the generator sites its versions rehearse (`replay`)."""


@dataclass(frozen=True)
class MaskRetrainConfig:
    """Fine-tuning and gate settings of the element-mask network."""

    train: MaskTrainConfig = field(
        default_factory=lambda: MaskTrainConfig(steps=300, learning_rate=3e-4, damaged_copies=2)
    )
    tolerance: float = 0.0
    """The candidate is promoted when its mAP >= current mAP - tolerance."""
    time_tolerance: float = 0.0
    """With a `review` gate: promoted only when its correction time <= current time * (1 + time_tolerance)."""
    min_labels: int = 1
    context_m: float = 10.0
    """Half the crops are centred on road cells within this distance of the reviewed elements (the rest on the
    elements): without them the network forgets that most road between elements holds nothing to draw."""
    replay_sites: int = 4
    """How many of the promoted version's own generator training sites are rehearsed (`replay`); 0: none."""
    replay_reconstructions: int = 0
    """How many of the reconstructions the promoted version trained on are rehearsed beside them (`replay`,
    read where they lie); 0, the default: none. In the loop bench six of them in half the crops got a candidate
    promoted that was slower for the annotator on every held-out set (README, "Rehearsing reconstructions")."""
    replay_share: float = 0.0
    """The share of training crops cut from the rehearsed sites (the rest from the corrected sites); off by
    default: in the loop bench it helped the held-out BEV sites and hurt the annotator on the reconstructed one
    (README, "Rehearsal while retraining")."""
    time_confidence: float = TIME_CONFIDENCE
    """With a `review` gate and each site's time: promoted only when it saves time in at least this share of
    bootstrap resamples of the validation sites (`models.vma.gate.saving_confidence`; 0: totals alone)."""
    start_version: str | None = None
    """The registry version the candidate is trained from (`vNNNN`); None, the default: the promoted one. Training
    an earlier version (the first, say) on every correction so far keeps one round's fine-tuning drift from
    compounding into the next; the candidate is gated against the promoted version either way."""

    def __post_init__(self) -> None:
        if self.tolerance < 0 or self.time_tolerance < 0 or self.min_labels < 1 or self.context_m < 0:
            raise ValueError(
                "MaskRetrainConfig: tolerance, time_tolerance and context_m >= 0 and min_labels >= 1 required"
            )
        for name in ("replay_sites", "replay_reconstructions"):
            if getattr(self, name) < 0:
                raise ValueError(f"MaskRetrainConfig.{name} must be >= 0, got {getattr(self, name)}")
        if not 0.0 <= self.replay_share < 1.0:
            raise ValueError(f"MaskRetrainConfig.replay_share must be in [0, 1), got {self.replay_share}")
        check_time_confidence(self.time_confidence, "MaskRetrainConfig")


def start_checkpoint(registry: Path, version: str | None) -> MaskCheckpoint | None:
    """The element-mask version `version` of `registry` (None when no version is named); a CheckpointError
    naming the registry and the version when it holds no such version or it is another kind of checkpoint."""
    if version is None:
        return None
    folder = registry / version
    if Path(version).name != version or not (folder / META).is_file():
        raise CheckpointError(f"{registry}: no version {version!r} to retrain from (no {folder / META})")
    return load_mask_checkpoint(folder)


def evaluate_mask_model(
    model: ElementMaskNet, sites: Sequence[ValidationEntry], review: ReviewGate | None = None
) -> dict[str, Any]:
    """Chamfer-AP of the network's proposals on validation sites, with the `review` figures (key "review")."""
    propose = product_proposer(model)
    metrics = evaluate_proposer(propose, sites)
    if review is not None:
        metrics["review"] = review(propose, sites)
    return metrics


def retrain_masks_from_corrections(
    registry: Path,
    corrections: Sequence[Corrections],
    validation_sites: Sequence[ValidationEntry],
    config: MaskRetrainConfig | None = None,
    *,
    review: ReviewGate | None = None,
    show_progress: bool = False,
) -> RetrainResult:
    """Fine-tune the promoted element-mask version of `registry` on corrections (with `config.replay_share` > 0
    rehearsing some of its own training sites, made again under `<registry>/replay-sites`); save the
    candidate; promote it if the gates pass. With `config.start_version` the candidate is that version trained
    on the corrections (it rehearses that version's sites, records it as its parent and what it saw), and it is
    still gated against the promoted version."""
    config = config or MaskRetrainConfig()
    started = time.perf_counter()
    current = load_mask_checkpoint(Path(registry))
    start = start_checkpoint(Path(registry), config.start_version) or current
    corrected_sites = [c.site for c in corrections]
    seen = seen_records(corrected_sites, start)
    refuse_seen_validation(seen, validation_sites, f"{start.path} with these corrections")
    if start is not current:  # the promoted version is scored on them too
        refuse_seen_validation(
            seen_records(corrected_sites, current), validation_sites, f"{current.path} with these corrections"
        )
    prepared, num_labels, num_negatives = [], 0, 0
    for k, item in enumerate(corrections):
        labels = vectors_from_annotations(item.annotations, LABEL_STATES)
        negatives = vectors_from_annotations(item.annotations, NEGATIVE_STATES)
        num_labels, num_negatives = num_labels + len(labels), num_negatives + len(negatives)
        if labels or negatives:
            rasters = load_site_rasters(item.site)
            seed = DAMAGE_SEED_BASE + 7919 * (k + 1) + config.train.seed
            prepared.append(
                training_site(
                    str(item.site),
                    rasters,
                    labels,
                    current.model.config,
                    config.train.damaged_copies,
                    seed,
                    centres_on=[*labels, *negatives],
                    context_m=config.context_m,
                )
            )
    if num_labels < config.min_labels:
        raise ValueError(
            f"retrain: {num_labels} accepted/fixed annotations, need at least {config.min_labels}"
        )
    current_metrics = evaluate_mask_model(current.model, validation_sites, review)
    rehearsed = (
        [
            *replay_sites(
                start,
                Path(registry) / REPLAY_FOLDER,
                config.replay_sites,
                start.model.config,
                config.train.damaged_copies,
                config.train.seed,
            ),
            *rehearsed_reconstructions(
                start, config.replay_reconstructions, start.model.config, config.train.seed
            ),
        ]
        if config.replay_share > 0
        else []
    )
    share = config.replay_share
    weights = (
        [(1.0 - share) / len(prepared)] * len(prepared) + [share / len(rehearsed)] * len(rehearsed)
        if rehearsed
        else None
    )
    candidate = load_mask_checkpoint(start.path).model  # a fresh copy to fine-tune
    fit_masks(
        candidate,
        [*prepared, *rehearsed],
        config.train,
        site_weights=weights,
        show_progress=show_progress,
    )
    round_to_stored(candidate.cpu())
    candidate_metrics = evaluate_mask_model(candidate, validation_sites, review)
    promoted = gate_passes(current_metrics, candidate_metrics, config)
    return save_candidate(
        Path(registry),
        candidate,
        CandidateRecord(
            start.path.name,
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
        {
            "kind": KIND,
            "replay": {"sites": [site.name for site in rehearsed], "share": config.replay_share},
            "gated_against": current.path.name,
        },
    )
