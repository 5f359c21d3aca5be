"""Annotator figures from known review events."""

from datetime import UTC, datetime, timedelta

import pytest

from app.backend.quality import ProposalDiff, ReviewEvent, annotator_figures

T0 = datetime(2025, 5, 1, 9, 0, tzinfo=UTC)
SAME = ProposalDiff(True, False, 0.0, 0, 0, 0, 0.0)
FIX = ProposalDiff(False, False, 0.3, 2, 0, 0, 0.4)


def at(minutes: float) -> datetime:
    """T0 plus some minutes."""
    return T0 + timedelta(minutes=minutes)


EVENTS = [
    ReviewEvent("ann", "divider", "accepted", at(0), SAME),
    ReviewEvent("ann", "divider", "fixed", at(5), FIX),
    ReviewEvent("ann", "boundary", "rejected", at(10)),
    ReviewEvent("ann", "divider", "accepted", at(60), SAME),  # after a 50 min idle gap: no active time
    ReviewEvent("ann", "divider", "created", at(63)),
    ReviewEvent("bob", "divider", "accepted", at(0), FIX),  # accepted with changes: not "unchanged"
]


def rows() -> dict[tuple[str, str], object]:
    """The figures keyed by (author, class)."""
    return {(row.author, row.cls): row for row in annotator_figures(reversed(EVENTS))}


def test_items_per_hour_excludes_idle_gaps() -> None:
    figures = rows()
    divider, boundary, total = figures["ann", "divider"], figures["ann", "boundary"], figures["ann", "all"]
    assert total.active_hours == pytest.approx(13 / 60)
    assert total.items_per_hour == pytest.approx(5 / (13 / 60))
    assert divider.active_hours == pytest.approx(8 / 60) and divider.items_per_hour == pytest.approx(30.0)
    assert boundary.items_per_hour == pytest.approx(12.0)


def test_acceptance_and_fix_displacement() -> None:
    figures = rows()
    divider = figures["ann", "divider"]
    assert (divider.items_handled, divider.proposals_reviewed, divider.accepted_unchanged) == (4, 3, 2)
    assert divider.accepted_unchanged_fraction == pytest.approx(2 / 3)
    assert divider.fixes == 1 and divider.mean_fix_displacement_m == pytest.approx(0.4)
    assert figures["ann", "boundary"].mean_fix_displacement_m is None


def test_single_event_has_no_rate() -> None:
    bob = rows()["bob", "divider"]
    assert bob.items_per_hour is None and bob.accepted_unchanged_fraction == 0.0
    assert list(rows()) == [
        ("ann", "all"),
        ("ann", "boundary"),
        ("ann", "divider"),
        ("bob", "all"),
        ("bob", "divider"),
    ]


def test_bad_action_and_naive_time() -> None:
    with pytest.raises(ValueError, match="action"):
        ReviewEvent("ann", "divider", "approved", T0)  # type: ignore[arg-type]
    assert ReviewEvent("ann", "divider", "created", datetime(2025, 5, 1)).at.tzinfo is UTC
