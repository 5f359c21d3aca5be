"""What a careful annotator does with one proposal, knowing the truth: accept it, fix it towards its true
element (counting the vertex edits that takes, merging the other proposals lying on the same element and
drawing the stretches none of them covers), or reject it; and what drawing a missed element costs.

Pure functions over polylines in one frame (metres); `session.work_queue` applies them to a queue of proposals.
"""

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
from shapely.geometry import LineString, Point

from annotations.geometry import resample_fixed, simplify
from app.review_effort.costs import ActionCosts
from cama_pipeline.evaluate.chamfer_ap import chamfer_distance

_SAMPLES = 50


@dataclass(frozen=True)
class SimulationConfig:
    """Tolerances of the scripted annotator."""

    match_m: float = 1.5
    """A proposal whose points lie within this mean distance of a true element's line is about that element
    (the loosest AP threshold): a correct piece of a long element counts, as it does for a person."""
    accept_m: float = 0.25
    """Within this Chamfer distance (and the right class) a proposal is accepted unchanged ..."""
    accept_max_m: float = 0.5
    """... provided no point of either is farther than this from the other (a visible kink, or a true corner
    cut or fallen short of, gets fixed)."""
    vertex_tolerance_m: float = 0.2
    """A vertex closer than this to the true line is left where it is."""
    simplify_m: float = 0.05
    """The vertices a person clicks: the true line simplified to this tolerance."""
    editor_simplify_m: float = 0.2
    """Tolerance of the editor's simplify command (its default), which a person may run before fixing."""
    split: bool = True
    """A proposal that runs along two true elements may be split in two (the editor's split, `split.py`); off: the
    annotator of the figures recorded before the split was modelled."""

    def __post_init__(self) -> None:
        if not 0 < self.accept_m <= self.match_m:
            raise ValueError(
                f"SimulationConfig: need 0 < accept_m <= match_m, got {self.accept_m}, {self.match_m}"
            )
        if self.accept_max_m < self.accept_m:
            raise ValueError(f"SimulationConfig: need accept_max_m >= accept_m, got {self.accept_max_m}")
        if min(self.vertex_tolerance_m, self.simplify_m, self.editor_simplify_m) <= 0:
            raise ValueError(
                "SimulationConfig: vertex_tolerance_m, simplify_m and editor_simplify_m must be > 0"
            )


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
    removed: int = 0
    merged: tuple[int, ...] = ()
    """Indices (into the other pending proposals) of the pieces of the same element merged into this one."""
    gap_runs: tuple[int, ...] = ()
    """True vertices missing, per stretch of the element no proposal covers."""
    simplified: bool = False
    """The editor's simplify was run on it first (fewer vertices to drag or delete)."""
    moved_whole: bool = False
    """It was moved whole onto its true line first (Ctrl/Cmd-drag), then its vertices edited."""
    split_off: "Decision | None" = None
    """The part split off the proposal (the editor's split) and corrected into a second true element: that part's
    own decision, booked within this one (no second inspection)."""
    split_inserted: bool = False
    """No vertex lay where the split goes: one was inserted on the segment first."""

    @property
    def added(self) -> int:
        return sum(self.gap_runs)

    @property
    def gaps(self) -> int:
        return len(self.gap_runs)

    def seconds(self, costs: ActionCosts) -> float:
        """Time this decision costs, from inspecting the element to its verdict. A missing stretch is either
        filled by inserting and dragging its vertices or drawn as a new piece and merged in, whichever is quicker."""
        fill = sum(
            min(
                k * costs.move_vertex_s,
                costs.draw_start_s + k * costs.add_vertex_s + costs.draw_finish_s + costs.merge_s,
            )
            for k in self.gap_runs
        )
        edits = (
            self.moved * costs.move_vertex_s
            + self.removed * costs.delete_vertex_s
            + (costs.relabel_s if self.relabel else 0.0)
            + len(self.merged) * costs.merge_s
            + fill
            + (costs.simplify_s if self.simplified else 0.0)
            + (costs.move_element_s if self.moved_whole else 0.0)
        )
        return costs.inspect_s + edits + costs.verdict_s + self._split_seconds(costs)

    def _split_seconds(self, costs: ActionCosts) -> float:
        """Time the split takes: the split itself, the vertex inserted for it, and the part's edits and verdict."""
        if self.split_off is None:
            return 0.0
        inserted = costs.add_vertex_s if self.split_inserted else 0.0
        return costs.split_s + inserted + self.split_off.seconds(costs) - costs.inspect_s

    @property
    def targets(self) -> tuple[int, ...]:
        """The true elements this decision covers: its own and the split-off part's."""
        own = () if self.target is None else (self.target,)
        return own + (() if self.split_off is None else self.split_off.targets)


def clicked_vertices(line: Polyline, config: SimulationConfig) -> np.ndarray:
    """The vertices a person would click to draw `line`: its points simplified."""
    return simplify(line.points, config.simplify_m)


def drawing_seconds(line: Polyline, config: SimulationConfig, costs: ActionCosts) -> float:
    """Time to draw `line` from nothing: start, one click per vertex (a ring's closing vertex is free), finish."""
    vertices = len(clicked_vertices(line, config)) - (1 if line.closed else 0)
    return costs.draw_start_s + vertices * costs.draw_vertex_s + costs.draw_finish_s


def chamfer(a: Polyline, b: Polyline) -> float:
    """Chamfer distance of the two shapes, each resampled to the same number of points (metres)."""
    return chamfer_distance(resample_fixed(a.points, _SAMPLES), resample_fixed(b.points, _SAMPLES))


def farthest_point(src: Polyline, dst: Polyline) -> tuple[float, np.ndarray]:
    """(distance to `dst`'s line, the point) of `src`'s vertex or evenly resampled point farthest from `dst`: one
    way of `worst_gap`."""
    line = LineString(dst.points)
    points = np.vstack([src.points, resample_fixed(src.points, _SAMPLES)])
    distances = [line.distance(Point(p)) for p in points]
    k = int(np.argmax(distances))
    return float(distances[k]), points[k]


def worst_gap(a: Polyline, b: Polyline) -> float:
    """The largest gap between the two shapes either way (vertices and resampled points): a kink of one, or a
    corner of the other that it cuts or falls short of."""
    return max(farthest_point(a, b)[0], farthest_point(b, a)[0])


def acceptable_as_is(proposal: Polyline, truth: Polyline, config: SimulationConfig) -> bool:
    """Whether the proposal's shape is close enough to the truth's to accept it unchanged (class aside)."""
    return chamfer(proposal, truth) <= config.accept_m and worst_gap(proposal, truth) <= config.accept_max_m


def _mean_distance_to(line: LineString, points: np.ndarray) -> float:
    """Mean distance of a polyline's resampled points to `line`: how well it lies along it, however short."""
    return float(np.mean([line.distance(Point(p)) for p in resample_fixed(points, _SAMPLES)]))


def _covered(target: np.ndarray, pieces: Sequence[np.ndarray], tolerance_m: float) -> np.ndarray:
    """Which target vertices lie within the stretch of the true line that some piece spans."""
    true_line = LineString(target)
    along = np.array([true_line.project(Point(p)) for p in target])
    covered = np.zeros(len(target), dtype=bool)
    for piece in pieces:
        spans = [true_line.project(Point(p)) for p in piece]
        covered |= (along >= min(spans) - tolerance_m) & (along <= max(spans) + tolerance_m)
    return covered


def _vertex_edits(
    pieces: Sequence[np.ndarray], target: np.ndarray, closed: bool, tolerance_m: float
) -> tuple[int, int, tuple[int, ...]]:
    """(moved, removed, gap_runs) that turn the pieces, merged, into `target`, counted as a person edits:
    vertices off the true line are deleted while there are more than the truth needs, the rest dragged onto
    it (vertices on the line stay); a true vertex (a corner) the pieces pass by farther than the tolerance is
    made by dragging one of those off vertices onto it, or else the piece's segment (the editor inserts a
    vertex where a segment is dragged); the true vertices no piece spans are missing, per stretch."""
    true_line = LineString(target)
    vertices = np.concatenate(pieces)
    if closed and len(vertices) > 1 and np.allclose(vertices[0], vertices[-1]):
        vertices = vertices[:-1]  # a ring's closing vertex is its first one
    off = int(sum(true_line.distance(Point(p)) > tolerance_m for p in vertices))
    corners = target[:-1] if closed else target
    removed = min(off, max(0, len(vertices) - len(corners)))
    moved = off - removed
    spanned = np.ones(len(corners), bool) if closed else _covered(target, pieces, tolerance_m)
    lines = [LineString(p) for p in pieces]
    missed = sum(
        min(line.distance(Point(c)) for line in lines) > tolerance_m
        for c, inside in zip(corners, spanned, strict=True)
        if inside
    )
    moved += max(0, missed - moved)
    if closed:
        return moved, removed, ()
    edges = np.diff(np.concatenate([[0], (~spanned).astype(int), [0]]))
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    return moved, removed, tuple(int(n) for n in ends - starts)


def nearest_truth(
    proposal: Polyline, truths: Sequence[Polyline], used: set[int], config: SimulationConfig
) -> int | None:
    """The unused true element the proposal lies along (mean distance within `match_m`), nearest first."""
    reach = [
        (_mean_distance_to(LineString(t.points), proposal.points), i)
        for i, t in enumerate(truths)
        if i not in used
    ]
    reach = [(d, i) for d, i in reach if d <= config.match_m]
    return min(reach)[1] if reach else None


def _to_line(points: np.ndarray, truth: Polyline) -> np.ndarray:
    """(N, 2) the vectors from each point to its nearest point on the true line."""
    line = LineString(truth.points)
    return np.array([line.interpolate(line.project(Point(p))).coords[0] for p in points]) - points


def offset_onto(points: np.ndarray, truth: Polyline) -> np.ndarray:
    """(2,) the shift that lays a polyline onto a true line beside it: the median of the vectors from its
    resampled points to their nearest points on the truth (a parallel offset, read off where it runs beside it)."""
    return np.asarray(np.median(_to_line(resample_fixed(points, _SAMPLES), truth), axis=0))


def move_offsets(points: np.ndarray, truth: Polyline) -> list[np.ndarray]:
    """The drags a person might move a polyline whole by: onto the truth as a whole (`offset_onto`), or taking it
    by one vertex and putting that vertex on the true line (the rest follows)."""
    return [offset_onto(points, truth), *_to_line(points, truth)]


def cheapest_fix(
    index: int,
    truth: Polyline,
    relabel: str | None,
    merged: tuple[int, ...],
    pieces: list[np.ndarray],
    config: SimulationConfig,
    costs: ActionCosts,
) -> Decision:
    """The quickest fix that turns the pieces (the proposal's first) into true element `index`'s clicked vertices:
    with or without the editor's simplify on them first (one key), and for a proposal alone with or without moving
    it whole first (one drag, `move_offsets`)."""
    target = clicked_vertices(truth, config)

    def fix(simplify_first: bool, move_by: np.ndarray | None) -> Decision:
        edited = pieces if move_by is None else [pieces[0] + move_by, *pieces[1:]]
        if simplify_first:
            edited = [simplify(p, config.editor_simplify_m) for p in edited]
        moved, removed, gap_runs = _vertex_edits(edited, target, truth.closed, config.vertex_tolerance_m)
        return Decision(
            "fix",
            index,
            target,
            relabel,
            moved,
            removed,
            merged,
            gap_runs,
            simplify_first,
            move_by is not None,
        )

    simplify_options = (False,) if truth.closed else (False, True)  # the editor does not simplify rings
    # a proposal alone may be moved whole first; pieces to merge are edited where they lie
    move_options = [None, *([] if merged else move_offsets(pieces[0], truth))]
    return min(
        (fix(s, m) for m in move_options for s in simplify_options),
        key=lambda d: d.seconds(costs),
    )


def decide(
    proposal: Polyline,
    truths: Sequence[Polyline],
    used: set[int],
    config: SimulationConfig,
    pending: Sequence[Polyline] = (),
    costs: ActionCosts | None = None,
) -> Decision:
    """The decision for one proposal: the unused true element it lies along is what it should become; the
    other `pending` proposals lying along that same element (and nearer to it than to any other) are merged in.
    A fix that would take longer than rejecting and drawing the element anew is not made: the proposal is
    rejected and the element drawn later, as a person short of time would."""
    costs = costs or ActionCosts()
    index = nearest_truth(proposal, truths, used, config)
    if index is None:
        return Decision("reject")
    truth = truths[index]
    relabel = truth.cls if truth.cls != proposal.cls else None
    if relabel is None and acceptable_as_is(proposal, truth, config):
        return Decision("accept", target=index)
    merged = tuple(
        k
        for k, other in enumerate(pending)
        if not truth.closed and nearest_truth(other, truths, used, config) == index
    )
    pieces = [proposal.points, *(pending[k].points for k in merged)]
    fix = cheapest_fix(index, truth, relabel, merged, pieces, config, costs)
    redraw_s = Decision("reject").seconds(costs) + drawing_seconds(truth, config, costs)
    return fix if fix.seconds(costs) < redraw_s else Decision("reject")


def road_length_km(truths: Sequence[Polyline]) -> float:
    """Kilometres of road: half the length of all road boundaries (a road has two)."""
    metres = sum(LineString(t.points).length for t in truths if t.cls == "boundary")
    return metres / 2 / 1000
