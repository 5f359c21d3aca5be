"""What a careful annotator does with one proposal, knowing the truth: accept it, fix it towards its true
element (counting the vertex edits that takes), or reject it; and what drawing a missed element costs.

Pure functions over polylines in one frame (site metres); the HTTP loop in `annotator.py` applies them.
"""

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
from shapely.geometry import LineString, Point

from annotations.geometry import simplify
from app.simulation.costs import ActionCosts
from cama_pipeline.evaluate.chamfer_ap import chamfer_distance, resample

_SAMPLES = 50


@dataclass(frozen=True)
class SimulationConfig:
    """Tolerances of the scripted annotator."""

    match_m: float = 1.5
    """A proposal within this Chamfer distance of a true element is about that element (the loosest AP threshold)."""
    accept_m: float = 0.25
    """Within this Chamfer distance (and the right class) a proposal is accepted unchanged."""
    vertex_tolerance_m: float = 0.2
    """A vertex closer than this to the true line is left where it is."""
    simplify_m: float = 0.05
    """The vertices a person clicks: the true line simplified to this tolerance."""

    def __post_init__(self) -> None:
        if not 0 < self.accept_m <= self.match_m:
            raise ValueError(
                f"SimulationConfig: need 0 < accept_m <= match_m, got {self.accept_m}, {self.match_m}"
            )
        if self.vertex_tolerance_m <= 0 or self.simplify_m <= 0:
            raise ValueError("SimulationConfig: vertex_tolerance_m and simplify_m must be > 0")


@dataclass(frozen=True, eq=False)
class Polyline:
    """A map vector: class and (N, 2) points; a closed ring repeats its first point last."""

    cls: str
    points: np.ndarray

    @property
    def closed(self) -> bool:
        return len(self.points) > 2 and bool(np.allclose(self.points[0], self.points[-1]))


@dataclass(frozen=True, eq=False)
class Decision:
    """What to do with one proposal and how many edits it takes."""

    kind: Literal["accept", "fix", "reject"]
    target: int | None = None
    """Index of the true element it was matched to."""
    points: np.ndarray | None = None
    """The corrected points (fix)."""
    relabel: str | None = None
    moved: int = 0
    added: int = 0
    removed: int = 0

    def seconds(self, costs: ActionCosts) -> float:
        """Time this decision costs, from inspecting the element to its verdict."""
        edits = (
            self.moved * costs.move_vertex_s
            + self.added * costs.add_vertex_s
            + self.removed * costs.delete_vertex_s
            + (costs.relabel_s if self.relabel else 0.0)
        )
        return costs.inspect_s + edits + costs.verdict_s


def clicked_vertices(line: Polyline, config: SimulationConfig) -> np.ndarray:
    """The vertices a person would click to draw `line`: its points simplified."""
    return simplify(line.points, config.simplify_m)


def drawing_seconds(line: Polyline, config: SimulationConfig, costs: ActionCosts) -> float:
    """Time to draw `line` from nothing: start, one click per vertex (a ring's closing vertex is free), finish."""
    vertices = len(clicked_vertices(line, config)) - (1 if line.closed else 0)
    return costs.draw_start_s + vertices * costs.draw_vertex_s + costs.draw_finish_s


def _chamfer(a: Polyline, b: Polyline) -> float:
    return chamfer_distance(resample(a.points, _SAMPLES), resample(b.points, _SAMPLES))


def _vertex_edits(proposal: Polyline, target: np.ndarray, tolerance_m: float) -> tuple[int, int, int]:
    """(moved, added, removed) vertices that turn the proposal into `target`, counted as a person edits:
    every vertex off the true line is dragged; an end vertex on the line but short of the true end is dragged
    out; vertices are added or deleted to match the true vertex count."""
    true_line, proposed_line = LineString(target), LineString(proposal.points)
    off = [true_line.distance(Point(p)) > tolerance_m for p in proposal.points]
    removed = max(0, len(proposal.points) - len(target))
    added = max(0, len(target) - len(proposal.points))
    moved = min(sum(off), len(proposal.points) - removed)
    closed = len(target) > 2 and bool(np.allclose(target[0], target[-1]))
    if not closed:
        for end in (target[0], target[-1]):
            nearest = int(np.argmin([np.linalg.norm(proposal.points[i] - end) for i in (0, -1)]))
            end_vertex_on_line = not off[0 if nearest == 0 else -1]
            if proposed_line.distance(Point(end)) > tolerance_m and end_vertex_on_line:
                moved += 1
    return moved, added, removed


def decide(
    proposal: Polyline, truths: Sequence[Polyline], used: set[int], config: SimulationConfig
) -> Decision:
    """The decision for one proposal: the nearest unused true element within reach is what it should be."""
    distances = [(_chamfer(proposal, t), i) for i, t in enumerate(truths) if i not in used]
    reachable = [(d, i) for d, i in distances if d <= config.match_m]
    if not reachable:
        return Decision("reject")
    distance, index = min(reachable)
    truth = truths[index]
    relabel = truth.cls if truth.cls != proposal.cls else None
    if distance <= config.accept_m and relabel is None:
        return Decision("accept", target=index)
    target = clicked_vertices(truth, config)
    moved, added, removed = _vertex_edits(proposal, target, config.vertex_tolerance_m)
    return Decision("fix", index, target, relabel, moved, added, removed)


def road_length_km(truths: Sequence[Polyline]) -> float:
    """Kilometres of road: half the length of all road boundaries (a road has two)."""
    metres = sum(LineString(t.points).length for t in truths if t.cls == "boundary")
    return metres / 2 / 1000
