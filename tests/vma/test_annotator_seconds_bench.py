"""`bench/annotator_seconds.py` books every second of the scripted annotator to a class and action, says why each
fix was needed, and its ceilings replace exactly the seconds they name."""

import numpy as np
import pytest

from app.review_effort.costs import ActionCosts
from app.review_effort.plan import Decision, Polyline, SimulationConfig
from app.review_effort.session import MemoryQueue, work_queue
from bench.annotator_seconds import booked_seconds, fix_reason, summary


def line(y: float, x0: float = 0.0, x1: float = 30.0) -> np.ndarray:
    return np.column_stack([np.linspace(x0, x1, 31), np.full(31, y)])


def worked_site() -> tuple[MemoryQueue, dict]:
    """A site with one proposal accepted, one fixed for a hooked end only, one fixed for lying off its line, one
    rejected and one true divider no proposal covers."""
    truths = [
        Polyline("divider", line(0.0)),
        Polyline("boundary", line(10.0)),
        Polyline("boundary", line(-10.0)),
        Polyline("divider", line(20.0)),
    ]
    hooked = line(10.05)
    hooked[-1] = [30.0, 10.85]  # 5 cm off its true line but for the end vertex, 0.85 m off
    queue = MemoryQueue(
        [
            (Polyline("divider", line(0.05)), 0.9),
            (Polyline("boundary", hooked), 0.9),
            (Polyline("boundary", line(-10.6)), 0.9),
            (Polyline("divider", line(45.0)), 0.9),
        ]
    )
    config, costs = SimulationConfig(), ActionCosts()
    log = work_queue(queue, truths, config, costs)
    figures = {
        "site": "synthetic",
        "correction_s": log.total_s,
        "drawing_s": 100.0,
        **booked_seconds(queue, log, truths, config, costs),
    }
    return queue, figures


def test_every_second_is_booked_to_a_class_and_action() -> None:
    queue, site = worked_site()
    booked = site["booked"]
    total = sum(entry["seconds"] for actions in booked.values() for entry in actions.values())
    assert total == pytest.approx(site["correction_s"])
    assert booked["divider"]["accept"]["count"] == 1
    assert booked["boundary"]["fix"]["count"] == 2
    assert booked["divider"]["reject"]["count"] == 1
    assert booked["divider"]["drawn"]["count"] == 1  # the divider at y = 20, which no proposal covered
    assert booked["road"]["scan"]["seconds"] > 0
    assert [t.cls for t in queue.drawn] == ["divider"]


def test_each_fix_says_whether_only_an_end_failed_the_acceptance() -> None:
    _, site = worked_site()
    hooked, off = sorted(site["fixes"], key=lambda fix: fix["chamfer_m"])
    assert hooked["within_chamfer"] and hooked["worst_gap_m"] == pytest.approx(0.85, abs=0.01)
    assert hooked["farthest_from_end_m"] == pytest.approx(0.0, abs=0.01)
    assert hooked["farthest_side"] == "proposal"
    assert not off["within_chamfer"] and off["chamfer_m"] == pytest.approx(0.6, abs=0.01)


def test_the_farthest_point_of_a_line_that_stops_short_is_the_truths_end() -> None:
    reason = fix_reason(
        Polyline("divider", line(0.0, 0.0, 29.0)), Polyline("divider", line(0.0)), SimulationConfig()
    )
    assert reason["farthest_side"] == "truth"
    assert reason["worst_gap_m"] == pytest.approx(1.0, abs=0.01)
    assert reason["farthest_from_end_m"] == pytest.approx(0.0, abs=0.01)


def test_the_ceilings_replace_the_seconds_they_name() -> None:
    _, site = worked_site()
    figures = summary({"per_site": [site, site]})
    assert figures["correction_s"] == pytest.approx(2 * site["correction_s"])
    assert figures["speed_up"] == pytest.approx(200.0 / figures["correction_s"])
    hooked = next(fix for fix in site["fixes"] if fix["within_chamfer"])
    accept_s = Decision("accept").seconds(ActionCosts())
    ceiling = figures["ceilings"]["fixes_within_chamfer_accepted"]["correction_s"]
    assert ceiling == pytest.approx(figures["correction_s"] - 2 * (hooked["seconds"] - accept_s), abs=0.05)
    drawn_s = site["booked"]["divider"]["drawn"]["seconds"]
    assert figures["ceilings"]["nothing_left_to_draw"]["correction_s"] == pytest.approx(
        figures["correction_s"] - 2 * drawn_s
    )
    reasons = figures["fix_reasons"]["boundary"]
    assert (
        reasons["within the Chamfer distance; farthest point at the end vertex (within 0.5 m of the end)"][
            "count"
        ]
        == 2
    )
    assert sum(r["count"] for r in reasons.values()) == 4


def test_a_crossings_outline_has_no_ends() -> None:
    square = np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 3.0], [0.0, 3.0], [0.0, 0.0]])
    reason = fix_reason(
        Polyline("ped_crossing", square + [0.6, 0.0]), Polyline("ped_crossing", square), SimulationConfig()
    )
    assert reason["farthest_from_end_m"] is None
    assert reason["worst_gap_m"] == pytest.approx(0.6, abs=0.01)
