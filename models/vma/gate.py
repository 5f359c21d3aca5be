"""The gates a retrained VMA candidate must pass to replace the promoted model: its validation mAP, the simulated
annotator's correction time on the validation sites, and how sure that time saving is across the sites.

Pure rules over the figures `models.vma.retrain.evaluate_model` (and its element-mask twin) write; numpy only, so
the backend's job parameters can name their defaults without loading torch.
"""

from collections.abc import Sequence
from typing import Any, Protocol

import numpy as np

TIME_CONFIDENCE = 0.9
"""The share of bootstrap resamples of the validation sites in which a candidate must save the annotator time
(`saving_confidence`), a one-sided 90 % level: in the loop bench two candidates whose totals on the thirteen
validation sites were 2.4 % and 1.5 % lower (the second faster on seven of the sites, a saving in 71 % of
resamples) were no faster on the held-out reconstructions and slower on the held-out BEV sites (README, "A
confident saving")."""


def check_time_confidence(value: float, owner: str) -> None:
    """ValueError naming the config unless 0 <= `value` < 1."""
    if not 0.0 <= value < 1.0:
        raise ValueError(f"{owner}: time_confidence must be in [0, 1), got {value}")


def passes_gate(current_map: float | None, candidate_map: float | None, tolerance: float) -> bool:
    """The evaluation gate: a candidate with no mAP never passes; one whose mAP did not drop does."""
    if candidate_map is None:
        return False
    return current_map is None or candidate_map >= current_map - tolerance


def passes_time_gate(current_s: float, candidate_s: float, tolerance: float) -> bool:
    """The review gate: the candidate's proposals take the annotator no longer than the current model's (plus a
    `tolerance` share)."""
    return candidate_s <= current_s * (1.0 + tolerance)


SAVING_RESAMPLES = 2000
"""Paired bootstrap resamples of the validation sites behind `saving_confidence` (seeded: the gate repeats)."""


def saving_confidence(current_s: Sequence[float], candidate_s: Sequence[float]) -> float:
    """How sure the candidate saves the annotator time over the validation sites rather than gaining on one by
    chance: the share of paired bootstrap resamples of the sites (each drawn with its two times) in which the
    candidate's total is below the current model's. One element's verdict moves a tiny site's time by 5-25 s, so
    a total a few per cent lower can be one lucky site (README, "Rehearsing reconstructions")."""
    if len(current_s) != len(candidate_s) or not current_s:
        raise ValueError(
            f"saving_confidence: per-site times of both models on the same sites needed, got {len(current_s)} "
            f"and {len(candidate_s)}"
        )
    saving = np.asarray(current_s, dtype=np.float64) - np.asarray(candidate_s, dtype=np.float64)
    rng = np.random.default_rng(0)
    picks = rng.integers(0, len(saving), size=(SAVING_RESAMPLES, len(saving)))
    return float((saving[picks].sum(axis=1) > 0).mean())


PER_SITE = "per_site_correction_s"
"""The key of each validation site's correction time in a review (`app.review_effort.review_time`)."""


def review_saving_confidence(current: dict[str, Any], candidate: dict[str, Any]) -> float | None:
    """`saving_confidence` of two models' reviews (`review_time`'s figures) from each site's time; None when either
    review lacks them (one recorded before they were)."""
    if PER_SITE not in current or PER_SITE not in candidate:
        return None
    return saving_confidence(current[PER_SITE], candidate[PER_SITE])


class GateTolerances(Protocol):
    """The gate's tolerances, as every retraining config carries them."""

    @property
    def tolerance(self) -> float: ...

    @property
    def time_tolerance(self) -> float: ...

    @property
    def time_confidence(self) -> float: ...


def gate_passes(current: dict[str, Any], candidate: dict[str, Any], config: GateTolerances) -> bool:
    """Both gates on two models' `evaluate_model` metrics: mAP, and the review time when both have one (with the
    sites' own times, its saving also at `config.time_confidence`, `saving_confidence`)."""
    if not passes_gate(current["mean_ap"], candidate["mean_ap"], config.tolerance):
        return False
    if "review" not in current or "review" not in candidate:
        return True
    ours, theirs = current["review"], candidate["review"]
    if not passes_time_gate(ours["correction_s"], theirs["correction_s"], config.time_tolerance):
        return False
    sure = review_saving_confidence(ours, theirs) if config.time_confidence > 0 else None
    return sure is None or sure >= config.time_confidence
