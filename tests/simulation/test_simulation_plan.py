"""The scripted annotator's decisions and costs on hand-made polylines."""

import numpy as np
import pytest

from app.simulation.costs import ActionCosts
from app.simulation.plan import Polyline, SimulationConfig, decide, drawing_seconds, road_length_km

CONFIG = SimulationConfig()
LINE = Polyline("divider", np.array([[0.0, 0.0], [10.0, 0.0], [20.0, 0.0]]))
CROSSWALK = Polyline(
    "ped_crossing", np.array([[30.0, 0.0], [34.0, 0.0], [34.0, 6.0], [30.0, 6.0], [30.0, 0.0]])
)


def test_a_proposal_on_the_truth_is_accepted_unchanged() -> None:
    decision = decide(Polyline("divider", LINE.points + [0.0, 0.1]), [LINE, CROSSWALK], set(), CONFIG)
    assert (decision.kind, decision.target, decision.moved) == ("accept", 0, 0)


def test_an_offset_proposal_is_fixed_by_moving_its_vertices_onto_the_truth() -> None:
    decision = decide(Polyline("divider", LINE.points + [0.0, 0.6]), [LINE], set(), CONFIG)
    assert decision.kind == "fix" and decision.relabel is None
    # three vertices off a straight truth that needs two: drag two, delete one
    assert decision.moved == 2 and decision.added == 0 and decision.removed == 1
    np.testing.assert_allclose(decision.points, LINE.points[[0, -1]])  # the straight truth needs two clicks


def test_a_short_proposal_is_extended_and_a_wrong_class_relabelled() -> None:
    short = Polyline("boundary", np.array([[0.0, 0.0], [12.0, 0.0]]))
    decision = decide(short, [LINE], set(), CONFIG)
    assert decision.kind == "fix" and decision.relabel == "divider"
    assert decision.moved == 1  # drag the short end out to 20 m


def test_a_proposal_far_from_any_truth_or_a_duplicate_is_rejected() -> None:
    assert decide(Polyline("divider", LINE.points + [0.0, 5.0]), [LINE], set(), CONFIG).kind == "reject"
    assert decide(LINE, [LINE], {0}, CONFIG).kind == "reject"


def test_costs_grow_with_the_edits_and_drawing_counts_clicks() -> None:
    costs = ActionCosts()
    accept = decide(LINE, [LINE], set(), CONFIG)
    fix = decide(Polyline("divider", LINE.points + [0.0, 0.6]), [LINE], set(), CONFIG)
    assert fix.seconds(costs) == pytest.approx(
        accept.seconds(costs) + 2 * costs.move_vertex_s + costs.delete_vertex_s
    )
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
