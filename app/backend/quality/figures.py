"""Figures per annotator and class: items handled per hour, proposals accepted unchanged, displacement of fixes.

These show whether the human-in-the-loop saves work. Active time is the sum of gaps between an annotator's
consecutive events that are no longer than an idle threshold; each gap is credited to the class of the event
that ends it, so the per-class times of an annotator add up to the annotator's total.
"""

import logging
from collections import defaultdict
from collections.abc import Iterable
from dataclasses import dataclass, field
from datetime import UTC, datetime, timedelta
from typing import Literal

import numpy as np

from app.backend.quality.diff import ProposalDiff

logger = logging.getLogger(__name__)

ReviewAction = Literal["accepted", "fixed", "rejected", "created"]
REVIEW_ACTIONS: frozenset[str] = frozenset({"accepted", "fixed", "rejected", "created"})
ALL_CLASSES = "all"
"""The `cls` of an annotator's summary row over every class."""
IDLE_GAP = timedelta(minutes=10)
"""Gaps between events longer than this are idle time, not work."""


@dataclass(frozen=True)
class ReviewEvent:
    """One review action by an annotator on one element; `diff` is the proposal-to-final diff when known."""

    author: str
    cls: str
    action: ReviewAction
    at: datetime
    diff: ProposalDiff | None = None

    def __post_init__(self) -> None:
        """Reject an unknown action; take a naive time to be UTC so all times compare."""
        if self.action not in REVIEW_ACTIONS:
            raise ValueError(
                f"action: unknown review action {self.action!r}; expected one of {sorted(REVIEW_ACTIONS)}"
            )
        if self.at.tzinfo is None:
            object.__setattr__(self, "at", self.at.replace(tzinfo=UTC))


@dataclass(frozen=True)
class AnnotatorFigures:
    """The figures of one annotator for one class (or `cls == "all"`); rates are None when undefined."""

    author: str
    cls: str
    items_handled: int
    active_hours: float
    items_per_hour: float | None
    proposals_reviewed: int
    accepted_unchanged: int
    accepted_unchanged_fraction: float | None
    fixes: int
    mean_fix_displacement_m: float | None


@dataclass
class _Tally:
    """Running counts for one (author, class) group."""

    items: int = 0
    active_s: float = 0.0
    reviewed: int = 0
    unchanged: int = 0
    fixes: int = 0
    displacements_m: list[float] = field(default_factory=list)

    def add(self, event: ReviewEvent, active_s: float) -> None:
        """Count one event and the active time that led up to it."""
        self.items += 1
        self.active_s += active_s
        if event.action != "created":
            self.reviewed += 1
        if event.action == "accepted" and (event.diff is None or event.diff.unchanged):
            self.unchanged += 1
        if event.action == "fixed":
            self.fixes += 1
            if event.diff is not None:
                self.displacements_m.append(event.diff.mean_displacement_m)

    def figures(self, author: str, cls: str) -> AnnotatorFigures:
        """The finished figures of this group."""
        hours = self.active_s / 3600.0
        return AnnotatorFigures(
            author=author,
            cls=cls,
            items_handled=self.items,
            active_hours=hours,
            items_per_hour=self.items / hours if hours > 0 else None,
            proposals_reviewed=self.reviewed,
            accepted_unchanged=self.unchanged,
            accepted_unchanged_fraction=self.unchanged / self.reviewed if self.reviewed else None,
            fixes=self.fixes,
            mean_fix_displacement_m=float(np.mean(self.displacements_m)) if self.displacements_m else None,
        )


def annotator_figures(
    events: Iterable[ReviewEvent], *, idle_gap: timedelta = IDLE_GAP
) -> list[AnnotatorFigures]:
    """Figures per annotator and class, plus one `cls="all"` row per annotator; sorted by author, then class."""
    if idle_gap <= timedelta(0):
        raise ValueError(f"idle_gap: must be positive, got {idle_gap}")
    by_author: dict[str, list[ReviewEvent]] = defaultdict(list)
    for event in events:
        by_author[event.author].append(event)
    rows: list[AnnotatorFigures] = []
    for author in sorted(by_author):
        tallies: dict[str, _Tally] = defaultdict(_Tally)
        previous: datetime | None = None
        for event in sorted(by_author[author], key=lambda e: e.at):
            gap = None if previous is None else event.at - previous
            active_s = gap.total_seconds() if gap is not None and gap <= idle_gap else 0.0
            tallies[event.cls].add(event, active_s)
            tallies[ALL_CLASSES].add(event, active_s)
            previous = event.at
        rows.extend(tallies[cls].figures(author, cls) for cls in sorted(tallies))
    logger.debug("annotator figures: %d rows for %d annotators", len(rows), len(by_author))
    return rows
