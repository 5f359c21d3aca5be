"""The human-in-the-loop policy of the VMA: when to retrain, which proposals enter pre-accepted, what QA samples.

Pure functions over plain values (the backend's jobs call them). The pre-accept threshold is calibrated on
the validation proposals of a checkpoint when it is saved (the lowest confidence above which proposals were
right often enough) and kept in its `checkpoint.json` under `preaccept_threshold`, so every promoted version
carries the threshold that fits its own confidence scale.
"""

import json
import logging
from collections.abc import Collection
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

from models.vma.checkpoint import META, CheckpointError, current_version

logger = logging.getLogger(__name__)

THRESHOLD_KEY = "preaccept_threshold"
"""Key of the calibrated threshold in a checkpoint's `checkpoint.json` (top level)."""


@dataclass(frozen=True)
class LoopConfig:
    """Settings of the correction loop."""

    retrain_after_corrections: int = 200
    """Retraining starts by itself after this many new accepted/fixed corrections (0: only on demand)."""
    preaccept_precision: float = 0.95
    """Proposals enter pre-accepted above the lowest confidence whose validation precision reaches this."""
    qa_sample_share: float = 0.1
    """Share of pre-accepted proposals sampled for the lead's QA."""
    min_preaccepted: int = 10
    """A threshold must keep at least this many validation proposals (a precision of 2 proposals is luck)."""

    def __post_init__(self) -> None:
        if self.retrain_after_corrections < 0:
            raise ValueError(
                f"LoopConfig.retrain_after_corrections must be >= 0, got {self.retrain_after_corrections}"
            )
        if not 0.0 < self.preaccept_precision <= 1.0:
            raise ValueError(
                f"LoopConfig.preaccept_precision must be in (0, 1], got {self.preaccept_precision}"
            )
        if not 0.0 <= self.qa_sample_share <= 1.0:
            raise ValueError(f"LoopConfig.qa_sample_share must be in [0, 1], got {self.qa_sample_share}")
        if self.min_preaccepted < 1:
            raise ValueError(f"LoopConfig.min_preaccepted must be >= 1, got {self.min_preaccepted}")


def calibrate_preaccept_threshold(
    confidences: ArrayLike, correct: ArrayLike, config: LoopConfig | None = None
) -> float | None:
    """The lowest confidence t such that validation proposals scoring >= t are right with precision >=
    `config.preaccept_precision` (and number at least `config.min_preaccepted`); None when no t reaches it."""
    config = config or LoopConfig()
    scores = np.asarray(confidences, dtype=np.float64)
    hits = np.asarray(correct, dtype=bool)
    if scores.shape != hits.shape or scores.ndim != 1:
        raise ValueError(f"calibrate: confidences {scores.shape} and correct {hits.shape} must be equal 1-D")
    order = np.argsort(-scores, kind="stable")
    scores, hits = scores[order], hits[order]
    precision = np.cumsum(hits) / np.arange(1, len(hits) + 1)
    # only cut between distinct scores: everything tied with the threshold is pre-accepted too
    last_of_tie = np.r_[scores[1:] != scores[:-1], True] if len(scores) else np.zeros(0, bool)
    ok = last_of_tie & (precision >= config.preaccept_precision)
    ok &= np.arange(1, len(hits) + 1) >= config.min_preaccepted
    if not ok.any():
        return None
    return float(scores[np.flatnonzero(ok)[-1]])


def preaccept_threshold(registry: Path) -> float | None:
    """The promoted checkpoint's calibrated threshold; None when it has none or cannot be read (nothing
    is pre-accepted then)."""
    try:
        meta = json.loads((current_version(Path(registry)) / META).read_text(encoding="utf-8"))
    except (CheckpointError, OSError, json.JSONDecodeError) as error:
        logger.warning("%s: no pre-accept threshold (%s)", registry, error)
        return None
    value = meta.get(THRESHOLD_KEY)
    return None if value is None else float(value)


def should_retrain(new_corrections: int, config: LoopConfig | None = None) -> bool:
    """Whether enough new accepted/fixed corrections arrived since the last retraining (0 turns it off)."""
    config = config or LoopConfig()
    return config.retrain_after_corrections > 0 and new_corrections >= config.retrain_after_corrections


def qa_sample(element_ids: Collection[int], share: float, seed: int) -> set[int]:
    """A reproducible sample of `share` of the ids for lead QA (at least one when share > 0 and ids exist)."""
    if not 0.0 <= share <= 1.0:
        raise ValueError(f"qa_sample: share must be in [0, 1], got {share}")
    ids = sorted(element_ids)
    if share == 0 or not ids:
        return set()
    count = min(len(ids), max(1, round(share * len(ids))))
    chosen = np.random.default_rng(seed).choice(len(ids), size=count, replace=False)
    return {ids[int(k)] for k in chosen}
