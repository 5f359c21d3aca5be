"""One annotator's session over a queue of proposals: lease, decide (`plan.decide`, or split the proposal in two
where that is quicker: `split.with_split`), apply, then draw what no proposal covered; the time booked per action
(`costs`).

The queue is anything with the `ReviewQueue` methods: the backend's annotator queue over HTTP
(`app.simulation.annotator`) or `MemoryQueue`, which hands proposals out in the backend's queue order for
proposals without lint findings (lowest confidence first, no confidence last, then in the order given) and keeps
the verdicts in memory.
"""

from collections import Counter, defaultdict
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

from app.review_effort.costs import ActionCosts
from app.review_effort.plan import (
    Decision,
    Polyline,
    SimulationConfig,
    decide,
    drawing_seconds,
    road_length_km,
)
from app.review_effort.split import with_split


@dataclass
class SessionLog:
    """What one simulated session did and the time it would have taken a person."""

    seconds: defaultdict[str, float] = field(default_factory=lambda: defaultdict(float))
    counts: Counter[str] = field(default_factory=Counter)
    road_km: float = 0.0

    @property
    def total_s(self) -> float:
        return float(sum(self.seconds.values()))

    def hours_per_km(self) -> float:
        """Person-hours per km of road."""
        return self.total_s / 3600 / self.road_km if self.road_km > 0 else float("nan")

    def as_dict(self) -> dict[str, Any]:
        return {
            "seconds": dict(self.seconds),
            "counts": dict(self.counts),
            "total_s": self.total_s,
            "road_km": self.road_km,
            "hours_per_km": self.hours_per_km(),
        }


class UnfinishedQueue(RuntimeError):
    """The queue still had items after the most a session may review."""


class ReviewQueue(Protocol):
    """Where the proposals wait: the next one, the others still waiting, and the annotator's changes."""

    def next(self) -> Any | None:
        """The next proposal to review (an opaque item), None when the queue is empty."""

    def polyline(self, item: Any) -> Polyline:
        """The item's class and points, in the frame of the truths."""

    def pending(self, item: Any) -> list[Any]:
        """The other items still waiting for a verdict."""

    def apply(self, item: Any, decision: Decision, pending: Sequence[Any]) -> None:
        """Carry out a decision: merged pending items deleted, a fix's points and class set, a split-off part made a
        new element and accepted, the verdict given."""

    def draw(self, truth: Polyline, config: SimulationConfig) -> None:
        """Draw a new element along a true one and accept it."""


def work_queue(
    queue: ReviewQueue,
    truths: Sequence[Polyline],
    config: SimulationConfig,
    costs: ActionCosts,
    *,
    max_items: int = 100_000,
) -> SessionLog:
    """Work the queue until it is empty, then draw the true elements no proposal covered."""
    log = SessionLog(road_km=road_length_km(truths))
    used: set[int] = set()
    for _ in range(max_items):
        item = queue.next()
        if item is None:
            break
        pending = queue.pending(item)
        proposal, around = queue.polyline(item), [queue.polyline(p) for p in pending]
        decision = decide(proposal, truths, used, config, around, costs)
        decision = with_split(decision, proposal, truths, used, config, around, costs)
        used.update(decision.targets)
        queue.apply(item, decision, pending)
        log.seconds[decision.kind] += decision.seconds(costs)
        log.counts[decision.kind] += 1
        log.counts["vertices_moved"] += decision.moved
        log.counts["elements_moved_whole"] += int(decision.moved_whole)
        log.counts["pieces_merged"] += len(decision.merged)
        log.counts["gaps_drawn"] += decision.gaps
        log.counts["splits"] += int(decision.split_off is not None)
    else:
        raise UnfinishedQueue(f"queue not empty after {max_items} items")
    draw_all(log, queue, [t for i, t in enumerate(truths) if i not in used], config, costs)
    return log


def draw_all(
    log: SessionLog,
    queue: ReviewQueue,
    truths: Sequence[Polyline],
    config: SimulationConfig,
    costs: ActionCosts,
) -> None:
    """Draw every one of `truths` and book it, then the scan of the whole site's road."""
    for truth in truths:
        queue.draw(truth, config)
        log.seconds["draw"] += drawn_seconds(truth, config, costs)
        log.counts["drawn"] += 1
    log.seconds["scan"] += log.road_km * 10 * costs.scan_per_100m_s


def drawn_seconds(truth: Polyline, config: SimulationConfig, costs: ActionCosts) -> float:
    """What drawing one true element costs in a session: its drawing and its verdict."""
    return drawing_seconds(truth, config, costs) + costs.verdict_s


def draw_from_scratch(
    queue: ReviewQueue, truths: Sequence[Polyline], config: SimulationConfig, costs: ActionCosts
) -> SessionLog:
    """Draw every true element on a site that has no proposals."""
    log = SessionLog(road_km=road_length_km(truths))
    draw_all(log, queue, truths, config, costs)
    return log


@dataclass
class MemoryQueue:
    """Proposals in memory, handed out in the backend's queue order (see the module docstring)."""

    proposals: list[tuple[Polyline, float | None]]
    """(polyline, confidence) in the frame of the truths."""
    waiting: list[int] = field(init=False)
    """Proposal indices not yet reviewed, in queue order."""
    verdicts: dict[int, Decision] = field(init=False, default_factory=dict)
    """The decision on each reviewed proposal (merged pieces have none: they were deleted)."""
    drawn: list[Polyline] = field(init=False, default_factory=list)

    def __post_init__(self) -> None:
        self.waiting = sorted(
            range(len(self.proposals)),
            key=lambda i: (self.proposals[i][1] is None, self.proposals[i][1] or 0.0, i),
        )

    def next(self) -> int | None:
        return self.waiting.pop(0) if self.waiting else None

    def polyline(self, item: int) -> Polyline:
        return self.proposals[item][0]

    def pending(self, item: int) -> list[int]:
        return [i for i in self.waiting if i != item]

    def apply(self, item: int, decision: Decision, pending: Sequence[int]) -> None:
        merged = {pending[k] for k in decision.merged}
        self.waiting = [i for i in self.waiting if i not in merged]
        self.verdicts[item] = decision

    def draw(self, truth: Polyline, config: SimulationConfig) -> None:
        self.drawn.append(truth)
