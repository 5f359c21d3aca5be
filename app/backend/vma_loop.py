"""The backend's one door to the VMA loop's policy: pre-accept threshold, when to retrain, the QA sample.

`models/vma/loop.py` (issue 6) is to own these rules; until it lands they live here with the same signatures,
so switching the backend over is an edit of this module only.
"""

import json
import logging
from collections.abc import Collection
from pathlib import Path

import numpy as np

from models.vma.checkpoint import META, CheckpointError, current_version

logger = logging.getLogger(__name__)

THRESHOLD_KEY = "preaccept_threshold"
"""Where a checkpoint's `checkpoint.json` keeps its calibrated pre-accept confidence (top level)."""


def preaccept_threshold(registry: Path) -> float | None:
    """The promoted checkpoint's calibrated pre-accept confidence; None when it has none (nothing pre-accepted)."""
    try:
        meta = json.loads((current_version(Path(registry)) / META).read_text(encoding="utf-8"))
    except (CheckpointError, FileNotFoundError, OSError, json.JSONDecodeError) as error:
        logger.warning("%s: no pre-accept threshold (%s)", registry, error)
        return None
    value = meta.get(THRESHOLD_KEY)
    return None if value is None else float(value)


def should_retrain(new_corrections: int, retrain_after: int) -> bool:
    """Whether enough new accepted/fixed corrections arrived since the last retrain (0 turns it off)."""
    return retrain_after > 0 and new_corrections >= retrain_after


def qa_sample(element_ids: Collection[int], share: float, seed: int) -> set[int]:
    """A reproducible sample of `share` of the ids (at least one when share > 0 and there are ids)."""
    ids = sorted(element_ids)
    if share <= 0 or not ids:
        return set()
    count = min(len(ids), max(1, round(share * len(ids))))
    chosen = np.random.default_rng(seed).choice(len(ids), size=count, replace=False)
    return {ids[int(k)] for k in chosen}
