"""The scripted annotator's decisions and costs on hand-made polylines."""

import numpy as np
import pytest

from app.review_effort.costs import ActionCosts
from app.review_effort.plan import (
    Polyline,
    SimulationConfig,
    decide,
    drawing_seconds,
    offset_onto,
    road_length_km,
)

CONFIG = SimulationConfig()
LINE = Polyline("divider", np.array([[0.0, 0.0], [10.0, 0.0], [20.0, 0.0]]))
ZIGZAG = Polyline("boundary", np.array([[10.0 * i, 2.0 * (i % 2)] for i in range(11)]))
CROSSWALK = Polyline(
    "ped_crossing", np.array([[30.0, 0.0], [34.0, 0.0], [34.0, 6.0], [30.0, 6.0], [30.0, 0.0]])
)


def test_a_proposal_on_the_truth_is_accepted_unchanged() -> None:
    decision = decide(Polyline("divider", LINE.points + [0.0, 0.1]), [LINE, CROSSWALK], set(), CONFIG)
    assert (decision.kind, decision.target, decision.moved) == ("accept", 0, 0)


def test_an_offset_proposal_is_fixed_by_moving_its_vertices_onto_the_truth() -> None:
    bent = ZIGZAG.points.copy()
    bent[[3, 4]] += [0.0, 0.6]
    decision = decide(Polyline("boundary", bent), [ZIGZAG], set(), CONFIG)
    assert decision.kind == "fix" and decision.relabel is None
    assert (decision.moved, decision.added, decision.removed) == (2, 0, 0)
    np.testing.assert_allclose(decision.points, ZIGZAG.points)


def test_a_fix_dearer_than_drawing_anew_is_a_reject() -> None:
    # three vertices off a straight truth that needs two, each by another offset (no drag of the whole lays more
    # than one on the line): the edits take longer than rejecting it and clicking the two true vertices
    bent = LINE.points + [[0.0, 0.6], [0.0, -0.6], [0.0, 0.3]]
    assert decide(Polyline("divider", bent), [LINE], set(), CONFIG).kind == "reject"


def test_a_line_beside_its_truth_is_moved_whole_then_edited() -> None:
    costs = ActionCosts()
    accept = decide(LINE, [LINE], set(), CONFIG)
    beside = decide(Polyline("divider", LINE.points + [0.0, 0.6]), [LINE], set(), CONFIG)
    assert beside.kind == "fix" and beside.moved_whole and beside.moved == 0  # one drag lays it on the line
    assert beside.seconds(costs) == pytest.approx(accept.seconds(costs) + costs.move_element_s)
    kinked = LINE.points + [0.0, 0.6]
    kinked[1] += [0.0, 0.8]  # and a vertex off the line after the move is dragged as well
    fixed = decide(Polyline("divider", kinked), [LINE], set(), CONFIG)
    assert fixed.moved_whole and fixed.moved + fixed.removed == 1
    assert not decide(
        Polyline("divider", LINE.points + [0.0, 0.1]), [LINE], set(), CONFIG
    ).moved_whole  # accepted
    np.testing.assert_allclose(offset_onto(LINE.points + [0.3, -0.4], LINE), [0.0, 0.4], atol=1e-9)


def test_a_short_proposal_is_extended_and_a_wrong_class_relabelled() -> None:
    short = Polyline("boundary", np.array([[0.0, 0.0], [12.0, 0.0]]))
    decision = decide(short, [LINE], set(), CONFIG)
    assert decision.kind == "fix" and decision.relabel == "divider"
    assert (decision.moved, decision.added, decision.gaps) == (0, 1, 1)  # the missing end is drawn on


def test_pieces_of_one_long_element_are_merged_and_only_the_uncovered_stretches_drawn() -> None:
    first = Polyline("boundary", ZIGZAG.points[0:4] + [0.0, 0.05])  # 0-30 m, on the line
    second = Polyline("boundary", ZIGZAG.points[6:9])  # 60-80 m
    elsewhere = Polyline("divider", np.array([[0.0, 40.0], [50.0, 40.0]]))
    decision = decide(first, [ZIGZAG], set(), CONFIG, [elsewhere, second])
    assert decision.kind == "fix" and decision.merged == (1,)
    # 40-50 m and 90-100 m are nobody's: four vertices in two stretches, each drawn and merged in
    assert (decision.moved, decision.added, decision.removed, decision.gaps) == (0, 4, 0, 2)
    costs = ActionCosts()
    alone = decide(first, [ZIGZAG], set(), CONFIG)
    assert (alone.added, alone.gaps) == (7, 1)
    assert decision.seconds(costs) == pytest.approx(
        alone.seconds(costs)
        - (
            costs.draw_start_s + 7 * costs.add_vertex_s + costs.draw_finish_s + costs.merge_s
        )  # one long stretch
        + costs.merge_s  # the second piece
        + 4 * costs.move_vertex_s  # two stretches of two: quicker to insert and drag than to draw
    )


def test_a_proposal_far_from_any_truth_or_a_duplicate_is_rejected() -> None:
    assert decide(Polyline("divider", LINE.points + [0.0, 5.0]), [LINE], set(), CONFIG).kind == "reject"
    # a piece of a long element is about that element even when the whole element is far longer
    assert decide(Polyline("divider", LINE.points[:2] / 4), [LINE], set(), CONFIG).kind == "fix"
    assert decide(LINE, [LINE], {0}, CONFIG).kind == "reject"


def test_costs_grow_with_the_edits_and_drawing_counts_clicks() -> None:
    costs = ActionCosts()
    accept = decide(ZIGZAG, [ZIGZAG], set(), CONFIG)
    short_kinked = ZIGZAG.points[:-1].copy()
    short_kinked[2] += [0.0, 0.6]
    fix = decide(Polyline("boundary", short_kinked), [ZIGZAG], set(), CONFIG)
    # one vertex dragged, the missing last one inserted and dragged too
    assert fix.seconds(costs) == pytest.approx(accept.seconds(costs) + 2 * costs.move_vertex_s)
    # dragging all ten off the line, each by another offset, would take longer than drawing it anew
    both_sides = ZIGZAG.points[:-1] + np.array([[0.0, (0.45 + 0.3 * i) * (-1) ** i] for i in range(10)])
    assert decide(Polyline("boundary", both_sides), [ZIGZAG], set(), CONFIG).kind == "reject"
    # all ten beside it by the same offset: one drag moves it whole, then the missing last vertex is drawn on
    beside = decide(Polyline("boundary", ZIGZAG.points[:-1] + [0.0, 0.6]), [ZIGZAG], set(), CONFIG)
    assert beside.kind == "fix" and beside.moved_whole
    assert drawing_seconds(LINE, CONFIG, costs) == pytest.approx(
        costs.draw_start_s + 2 * costs.draw_vertex_s + costs.draw_finish_s
    )
    # a ring of four corners takes four clicks: the closing vertex is the first one again
    assert drawing_seconds(CROSSWALK, CONFIG, costs) == pytest.approx(
        costs.draw_start_s + 4 * costs.draw_vertex_s + costs.draw_finish_s
    )


def test_road_length_is_half_the_boundaries_and_bad_settings_are_refused() -> None:
    sides = [Polyline("boundary", np.array([[0.0, y], [500.0, y]])) for y in (0.0, 10.0)]
    assert road_length_km([*sides, LINE]) == pytest.approx(0.5)
    with pytest.raises(ValueError, match="accept_m"):
        SimulationConfig(accept_m=2.0, match_m=1.0)
    with pytest.raises(ValueError, match="move_vertex_s"):
        ActionCosts(move_vertex_s=-1.0)


def test_a_densely_wiggled_stretch_is_simplified_before_it_is_fixed() -> None:
    tail = np.array([[x, 2.0 - abs(x - 90.0) / 5.0 + 0.6] for x in np.arange(80.0, 100.5, 1.0)])
    proposal = Polyline("boundary", np.vstack([ZIGZAG.points[:8], tail]))  # last 20 m: 21 vertices, 0.6 m off
    decision = decide(proposal, [ZIGZAG], set(), CONFIG)
    assert decision.kind == "fix" and decision.simplified
    assert decision.moved + decision.removed <= 4  # the simplified stretch keeps a handful of vertices


def test_corners_a_proposal_misses_are_dragged_even_when_its_vertices_lie_on_the_true_lines() -> None:
    short = CROSSWALK.points.copy()
    short[[2, 3], 1] -= 0.8  # the far side 0.8 m short: its corners still lie on the long sides
    decision = decide(Polyline("ped_crossing", short), [CROSSWALK], set(), CONFIG)
    assert (decision.kind, decision.moved, decision.added) == ("fix", 2, 0)
    corner = Polyline("boundary", np.array([[0.0, 0.0], [20.0, 0.0], [20.0, 20.0]]))
    cut = Polyline("boundary", np.array([[0.0, 0.0], [19.0, 0.0], [20.0, 1.0], [20.0, 20.0]]))
    assert decide(cut, [corner], set(), CONFIG).moved == 1  # the cut corner is dragged out


def test_a_ring_with_one_corner_off_costs_one_drag_not_two_for_its_closing_vertex() -> None:
    ring = CROSSWALK.points.copy()
    ring[[0, -1]] += [0.0, -0.6]  # the first corner, repeated as the closing vertex
    decision = decide(Polyline("ped_crossing", ring), [CROSSWALK], set(), CONFIG)
    assert (decision.kind, decision.moved, decision.removed) == ("fix", 1, 0)
