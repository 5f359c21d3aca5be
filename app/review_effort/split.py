"""A proposal that runs along two true elements, split in two with the editor's split (K) and each part corrected.

The network bridges what the truth an annotator works to leaves apart: a divider traced straight across the stretch
a parked car hid (the truth is cut where the cameras saw no paint), or two dashes' lines joined end to end. Without
a split the annotator fixes the proposal into one of the two elements, deleting the vertices on the other, and then
draws that other one from nothing; with the editor's split it points at a vertex where the two meet (inserting one on
the segment if none lies there), presses K, and corrects the two parts where they lie. A careful person takes the
quicker of the two ways, and so does this module: `with_split` replaces `plan.decide`'s decision by the split only
where the split costs less than that decision plus drawing the element it leaves out.

Only an open proposal not merged with others is split, only into two parts of its own class, and only where no other
proposal waiting in the queue lies along either element (that proposal would cover it without a split).
"""

from collections.abc import Sequence
from dataclasses import replace

import numpy as np
from shapely.geometry import LineString, Point

from annotations.geometry import arc_lengths, resample_fixed
from app.review_effort.costs import ActionCosts
from app.review_effort.plan import (
    Decision,
    Polyline,
    SimulationConfig,
    acceptable_as_is,
    cheapest_fix,
    drawing_seconds,
    nearest_truth,
)

SAMPLE_M = 0.25
"""Spacing of the points along a proposal at which the element it runs along is read."""


def runs_along(
    proposal: Polyline, truths: Sequence[Polyline], used: set[int], config: SimulationConfig
) -> tuple[int, int, float] | None:
    """(a, b, station): the proposal runs first along unused true element a, then along b (both of its class),
    and `station` (metres along it) lies midway between the last point nearest a and the first nearest b; None
    unless its points, each given to the nearest such element within `config.match_m`, fall in exactly two runs."""
    line = LineString(proposal.points)
    count = max(2, int(np.ceil(line.length / SAMPLE_M)) + 1)
    samples = resample_fixed(proposal.points, count)
    candidates = [i for i, t in enumerate(truths) if i not in used and t.cls == proposal.cls]
    if len(candidates) < 2:
        return None
    lines = [LineString(truths[i].points) for i in candidates]
    distance = np.array([[other.distance(Point(p)) for other in lines] for p in samples])
    nearest = np.where(
        distance.min(axis=1) <= config.match_m, np.asarray(candidates)[distance.argmin(axis=1)], -1
    )
    claimed = np.flatnonzero(nearest >= 0)
    labels = nearest[claimed]
    changes = np.flatnonzero(np.diff(labels) != 0)
    if len(changes) != 1:
        return None
    last_a, first_b = claimed[changes[0]], claimed[changes[0] + 1]
    step = line.length / (count - 1)
    return int(labels[0]), int(labels[-1]), (last_a + first_b) / 2 * step


def split_at(points: np.ndarray, station: float) -> list[tuple[np.ndarray, np.ndarray, bool]]:
    """The ways to split a polyline near `station` (metres along it): at its interior vertex nearest the station,
    and at a vertex inserted there; each (head, tail, inserted), the two parts sharing the split vertex."""
    along = arc_lengths(points)
    options = []
    if len(points) > 2:
        k = 1 + int(np.argmin(np.abs(along[1:-1] - station)))
        options.append((points[: k + 1], points[k:], False))
    if 0.0 < station < along[-1]:
        j = int(np.searchsorted(along, station))
        inserted = np.asarray(LineString(points).interpolate(station).coords[0])
        options.append((np.vstack([points[:j], inserted]), np.vstack([inserted, points[j:]]), True))
    return options


def part_decision(
    points: np.ndarray, truths: Sequence[Polyline], index: int, config: SimulationConfig, costs: ActionCosts
) -> Decision:
    """One part of a split proposal made into true element `index`: kept as it is where acceptable (its points),
    else fixed the quickest way."""
    truth = truths[index]
    if acceptable_as_is(Polyline(truth.cls, points), truth, config):
        return Decision("fix", index, points)
    return cheapest_fix(index, truth, None, (), [points], config, costs)


def with_split(
    decision: Decision,
    proposal: Polyline,
    truths: Sequence[Polyline],
    used: set[int],
    config: SimulationConfig,
    pending: Sequence[Polyline],
    costs: ActionCosts,
) -> Decision:
    """`decision` (`plan.decide`'s for this proposal) or, where it costs less, the proposal split in two: the
    decision for its first part with the second part's as `split_off` (see the module docstring)."""
    if not config.split or proposal.closed or decision.kind == "accept" or decision.merged:
        return decision
    found = runs_along(proposal, truths, used, config)
    if found is None:
        return decision
    a, b, station = found
    if decision.target not in (None, a, b):
        return decision
    claimed = {nearest_truth(other, truths, used, config) for other in pending}
    if a in claimed or b in claimed:
        return decision
    left_out = [x for x in (a, b) if x != decision.target]
    otherwise_s = decision.seconds(costs) + sum(
        drawing_seconds(truths[x], config, costs) + costs.verdict_s for x in left_out
    )
    best, best_s = decision, otherwise_s
    for head, tail, inserted in split_at(proposal.points, station):
        if nearest_truth(Polyline(proposal.cls, head), truths, used, config) != a:
            continue
        if nearest_truth(Polyline(proposal.cls, tail), truths, used | {a}, config) != b:
            continue
        first = part_decision(head, truths, a, config, costs)
        second = part_decision(tail, truths, b, config, costs)
        split = replace(first, split_off=second, split_inserted=inserted)
        if split.seconds(costs) < best_s:
            best, best_s = split, split.seconds(costs)
    return best
