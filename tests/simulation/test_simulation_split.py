"""The scripted annotator's split: a proposal running along two true elements is split where they meet."""

from dataclasses import replace

import numpy as np
import pytest

from app.review_effort.costs import ActionCosts
from app.review_effort.plan import Polyline, SimulationConfig, decide, drawing_seconds
from app.review_effort.session import MemoryQueue, work_queue
from app.review_effort.split import runs_along, split_at, with_split

CONFIG, COSTS = SimulationConfig(), ActionCosts()
# one divider cut where a parked car hid 10-13 m: two elements in the truth an annotator works to
PIECES = [
    Polyline("divider", np.array([[0.0, 0.0], [10.0, 0.0]])),
    Polyline("divider", np.array([[13.0, 0.0], [25.0, 0.0]])),
]
BRIDGED = Polyline("divider", np.array([[0.0, 0.0], [25.0, 0.0]]))


def _split(proposal: Polyline, pending: list[Polyline] = [], config: SimulationConfig = CONFIG):  # noqa: B006
    decision = decide(proposal, PIECES, set(), config, pending, COSTS)
    return decision, with_split(decision, proposal, PIECES, set(), config, pending, COSTS)


def test_a_proposal_bridging_a_gap_is_split_where_the_elements_meet() -> None:
    assert runs_along(BRIDGED, PIECES, set(), CONFIG) == (0, 1, pytest.approx(11.5, abs=0.25))  # equidistant
    whole, split = _split(BRIDGED)
    assert whole.kind == "reject"  # along neither element as a whole: without a split both are drawn
    assert split.targets == (0, 1) and split.split_inserted  # no vertex lay in the gap: one was inserted
    # each part's end in the gap (1.5 m past its element) is dragged onto it
    assert (split.moved, split.split_off.moved) == (1, 1)
    np.testing.assert_allclose(split.points, PIECES[0].points)
    np.testing.assert_allclose(split.split_off.points, PIECES[1].points)
    edits = 2 * COSTS.move_vertex_s + 2 * COSTS.verdict_s + COSTS.split_s + COSTS.add_vertex_s
    assert split.seconds(COSTS) == pytest.approx(COSTS.inspect_s + edits)
    redraw = sum(drawing_seconds(p, CONFIG, COSTS) + COSTS.verdict_s for p in PIECES)
    assert split.seconds(COSTS) < whole.seconds(COSTS) + redraw


def test_a_vertex_in_the_gap_is_split_at_without_inserting_one() -> None:
    with_vertex = Polyline("divider", np.array([[0.0, 0.0], [11.0, 0.0], [25.0, 0.0]]))
    _, split = _split(with_vertex)
    assert split.targets == (0, 1) and not split.split_inserted
    heads = [head[-1].tolist() for head, _, _ in split_at(with_vertex.points, 11.5)]
    assert heads == [[11.0, 0.0], [11.5, 0.0]]  # at the nearest vertex, or at one inserted at the station


def test_no_split_where_it_is_off_or_another_proposal_covers_an_element() -> None:
    whole, split = _split(BRIDGED, config=replace(CONFIG, split=False))
    assert split is whole
    covering = Polyline("divider", PIECES[1].points + [0.0, 0.05])
    whole, split = _split(BRIDGED, pending=[covering])
    assert split is whole  # the other proposal is accepted as the second element later
    on_one = Polyline("divider", PIECES[1].points + [0.0, 0.3])
    whole, split = _split(on_one)
    assert split is whole and split.split_off is None


def test_a_session_books_the_split_and_draws_neither_part() -> None:
    queue = MemoryQueue([(BRIDGED, 0.5)])
    log = work_queue(queue, PIECES, CONFIG, COSTS)
    assert (log.counts["splits"], log.counts["drawn"], len(queue.drawn)) == (1, 0, 0)
    without = work_queue(MemoryQueue([(BRIDGED, 0.5)]), PIECES, replace(CONFIG, split=False), COSTS)
    assert (without.counts["splits"], without.counts["drawn"]) == (0, 2)
    assert log.total_s < without.total_s
