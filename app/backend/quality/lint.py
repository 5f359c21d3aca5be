"""Map lint over a site, kept up to date element by element.

`SiteLint` holds a site's elements and their findings: findings of one element (self crossings, bad
crosswalks), of pairs of elements within reach of each other (crossing dividers, divider spacing, boundaries
broken at a window border) and of divider ends (dangling). `update` lints only what an edit can change: the
changed elements on their own, their pairs with the elements within reach (found by an STRtree of element
boxes), and the ends of the dividers within `end_connect_m` of their old or new geometry; every other result is
kept. Whether another divider lies between a spacing pair is checked when the findings are put together.
`lint` is one update over all elements and the `find_*` functions give its rules one at a time.
"""

import logging
import time
from collections import Counter, defaultdict
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np
import shapely
from shapely.geometry import Polygon

from annotations.schema import MapElement
from app.backend.quality.lint_rules import (
    ElementView,
    EndContext,
    LintConfig,
    LintFinding,
    Severity,
    SpacingCandidate,
    bad_crosswalk_of,
    broken_boundaries_of,
    crossing_of,
    dangling_ends_of,
    self_intersection_of,
    spacing_candidate_of,
    unblocked_spacing,
)
from app.backend.quality.polyline import as_geometry_array

logger = logging.getLogger(__name__)

__all__ = [
    "ElementView",
    "LintConfig",
    "LintFinding",
    "LintWork",
    "Severity",
    "SiteLint",
    "find_bad_crosswalks",
    "find_broken_boundaries",
    "find_crossing_dividers",
    "find_dangling_divider_ends",
    "find_divider_spacing",
    "find_self_intersections",
    "lint",
]

PairKey = tuple[str, str]
"""Two element ids, the first ranked before the second."""


@dataclass
class LintWork:
    """What one update linted: elements checked on their own, element pairs compared (divider-divider and
    boundary-boundary pairs within reach), dividers whose ends were checked, and the ids of changed elements
    left for a later update (the deadline passed)."""

    elements: int = 0
    pairs: int = 0
    divider_ends: int = 0
    pending: list[str] = field(default_factory=list)


@dataclass
class _PairFindings:
    """The findings of one pair of elements (the spacing one before the between check)."""

    crossing: LintFinding | None = None
    spacing: SpacingCandidate | None = None
    broken: list[LintFinding] = field(default_factory=list)

    def __bool__(self) -> bool:
        return self.crossing is not None or self.spacing is not None or bool(self.broken)


class SiteLint:
    """The lint of one site's elements, updated element by element.

    `rank` orders elements (which of a pair is "first" for the spacing samples, and the order of the findings);
    by default, the order in which they were first given.
    """

    def __init__(
        self,
        *,
        config: LintConfig = LintConfig(),  # noqa: B008 - frozen, so a shared default is safe
        region: Polygon | None = None,
        rank: Callable[[str], int] | None = None,
    ) -> None:
        self.config, self.region = config, region
        self._rank = rank
        self._arrival: dict[str, int] = {}
        self._arrivals = 0
        self.views: dict[str, ElementView] = {}
        self._own: dict[str, list[LintFinding]] = {}
        self._dangling: dict[str, list[LintFinding]] = {}
        self._pairs: dict[PairKey, _PairFindings] = {}
        self._partners: dict[str, set[str]] = defaultdict(set)
        self.work = LintWork()
        """What the last update linted."""

    @property
    def reach_m(self) -> float:
        """How far apart (bounding boxes) two elements may be and still share a pair finding."""
        return max(self.config.spacing_search_m, self.config.break_gap_m)

    def rank(self, element_id: str) -> int:
        """Position of an element in the site's order."""
        return self._rank(element_id) if self._rank is not None else self._arrival[element_id]

    def update(
        self,
        changed: Iterable["ElementView | MapElement"],
        removed: Iterable[str] = (),
        *,
        deadline: float | None = None,
    ) -> LintWork:
        """Take new or changed elements and removed ids, and lint what they can affect; what was linted.

        Changed elements are taken one by one, each compared with the elements within reach as they stand
        then; once `time.monotonic()` passes `deadline` (after the first), the rest are left out and listed in
        the work's `pending`. The state stays consistent: it holds their previous version, or nothing for new
        ones. Removals are always taken.
        """
        views = [ElementView.of(element) for element in changed]
        repeated = sorted(i for i, n in Counter(view.id for view in views).items() if n > 1)
        if repeated:
            raise ValueError(f"elements: ids must be unique, {repeated} repeat")
        gone = set(removed) - {view.id for view in views}
        self.work = LintWork()
        before = [self.views[i] for i in sorted(gone) if i in self.views]
        for element_id in gone:
            self._forget(element_id)
            self._arrival.pop(element_id, None)
        neighbours = self._neighbours(views)
        taken: list[ElementView] = []
        for view, near in zip(views, neighbours, strict=True):
            if taken and deadline is not None and time.monotonic() >= deadline:
                break
            if view.id in self.views:
                before.append(self.views[view.id])
            self._forget(view.id)
            self.views[view.id] = view
            if view.id not in self._arrival:
                self._arrival[view.id], self._arrivals = self._arrivals, self._arrivals + 1
            self._own[view.id] = [
                f for f in (self_intersection_of(view), bad_crosswalk_of(view)) if f is not None
            ]
            self.work.pairs += sum(self._compare(view, other) for other in near if other != view.id)
            taken.append(view)
        self.work.elements = len(taken)
        self.work.divider_ends = self._check_ends(before, taken)
        self.work.pending = [view.id for view in views[len(taken) :]]
        logger.debug("lint update: %s over %d elements", self.work, len(self.views))
        return self.work

    def _neighbours(self, views: Sequence[ElementView]) -> list[set[str]]:
        """For each changed element, the ids of elements (as they stand now, or as changed) whose boxes lie
        within reach of its new box; which version of each is compared is decided when it is taken."""
        if not views:
            return []
        everything = [*self.views.values(), *views]
        boxes = shapely.box(*np.asarray([view.bounds for view in everything], dtype=float).T)
        query, hit = shapely.STRtree(boxes).query(
            boxes[len(self.views) :], predicate="dwithin", distance=self.reach_m
        )
        near: list[set[str]] = [set() for _ in views]
        for q, h in zip(query.tolist(), hit.tolist(), strict=True):
            near[q].add(everything[h].id)
        return near

    def _forget(self, element_id: str) -> None:
        """Drop an element and every result it takes part in."""
        self.views.pop(element_id, None)
        self._own.pop(element_id, None)
        self._dangling.pop(element_id, None)
        for partner in self._partners.pop(element_id, set()):
            self._pairs.pop(self._key(element_id, partner), None)
            self._partners[partner].discard(element_id)

    def _key(self, one: str, other: str) -> PairKey:
        return (one, other) if self.rank(one) < self.rank(other) else (other, one)

    def _comparable(self, first: ElementView, second: ElementView) -> bool:
        """Whether the rules compare these two elements at all."""
        return first.cls == second.cls == "divider" or (
            first.cls == second.cls == "boundary" and self.config.window_size_m is not None
        )

    def _compare(self, view: ElementView, other_id: str) -> bool:
        """Run the pair rules on a changed element and another as it stands (if it is within reach and the
        rules compare the two); whether they were compared."""
        other = self.views.get(other_id)
        if other is None or not self._comparable(view, other) or not self._within_reach(view, other):
            return False
        first, second = (view, other) if self.rank(view.id) < self.rank(other.id) else (other, view)
        if first.cls == "divider":
            found = _PairFindings(
                crossing=crossing_of(first, second, self.config),
                spacing=spacing_candidate_of(first, second, self.config),
            )
        else:
            found = _PairFindings(broken=broken_boundaries_of(first, second, self.config))
        if found:
            self._pairs[(first.id, second.id)] = found
            self._partners[first.id].add(second.id)
            self._partners[second.id].add(first.id)
        return True

    def _within_reach(self, view: ElementView, other: ElementView) -> bool:
        """Whether the two boxes are at most `reach_m` apart."""
        (ax0, ay0, ax1, ay1), (bx0, by0, bx1, by1) = view.bounds, other.bounds
        dx, dy = max(bx0 - ax1, ax0 - bx1, 0.0), max(by0 - ay1, ay0 - by1, 0.0)
        return bool(np.hypot(dx, dy) <= self.reach_m * (1.0 + 1e-9))  # a hair of slack for rounding

    def _check_ends(self, before: Sequence[ElementView], after: Sequence[ElementView]) -> int:
        """Check the ends of changed dividers and of dividers with an end within reach of a changed element's
        old or new geometry; the number of dividers checked."""
        if not before and not after:
            return 0
        context = EndContext.of(list(self.views.values()), self.region)
        influence = [
            view.anchor if view.cls in ("boundary", "ped_crossing") else shapely.MultiPoint(list(view.ends))
            for view in [*before, *after]
        ]
        _query, hit = context.end_tree.query(
            as_geometry_array(influence), predicate="dwithin", distance=self.config.end_connect_m
        )
        touched = {view.id for view in after} | {context.end_owner[h] for h in hit}
        dividers = [self.views[i] for i in touched if i in self.views and self.views[i].cls == "divider"]
        self._dangling.update(dangling_ends_of(dividers, context, self.config))
        return len(dividers)

    def _ranked(self, ids: Iterable[str]) -> list[str]:
        return sorted(ids, key=self.rank)

    def _ranked_pairs(self) -> list[_PairFindings]:
        keys = sorted(self._pairs, key=lambda key: (self.rank(key[0]), self.rank(key[1])))
        return [self._pairs[key] for key in keys]

    def dangling_findings(self) -> list[LintFinding]:
        """Divider ends that stop in the open, dividers in order."""
        return [f for i in self._ranked(self._dangling) for f in self._dangling[i]]

    def self_intersection_findings(self) -> list[LintFinding]:
        """Dividers and boundaries that cross themselves."""
        return [f for i in self._ranked(self._own) for f in self._own[i] if f.code == "self_intersection"]

    def crossing_findings(self) -> list[LintFinding]:
        """Pairs of dividers that cross away from their ends."""
        return [pair.crossing for pair in self._ranked_pairs() if pair.crossing is not None]

    def spacing_findings(self) -> list[LintFinding]:
        """Neighbouring parallel dividers too close together or with a gap for a missing divider."""
        candidates = [pair.spacing for pair in self._ranked_pairs() if pair.spacing is not None]
        dividers = [view for view in self.views.values() if view.cls == "divider"]
        return unblocked_spacing(candidates, dividers)

    def broken_boundary_findings(self) -> list[LintFinding]:
        """Boundary ends that nearly meet at a window border."""
        return [f for pair in self._ranked_pairs() for f in pair.broken]

    def crosswalk_findings(self) -> list[LintFinding]:
        """Crosswalks that are not closed or not simple."""
        return [f for i in self._ranked(self._own) for f in self._own[i] if f.code.startswith("crosswalk_")]

    def findings(self) -> list[LintFinding]:
        """Every finding, rule by rule."""
        return [
            *self.dangling_findings(),
            *self.self_intersection_findings(),
            *self.crossing_findings(),
            *self.spacing_findings(),
            *self.broken_boundary_findings(),
            *self.crosswalk_findings(),
        ]


def _linted(
    elements: Iterable["MapElement | ElementView"], config: LintConfig, region: Polygon | None = None
) -> SiteLint:
    state = SiteLint(config=config, region=region)
    state.update(elements)
    return state


def find_dangling_divider_ends(
    views: Sequence[ElementView], config: LintConfig, region: Polygon | None = None
) -> list[LintFinding]:
    """Divider ends that stop in the open: not near another element's end, a boundary, a crosswalk or the border."""
    return _linted(views, config, region).dangling_findings()


def find_self_intersections(views: Sequence[ElementView], config: LintConfig) -> list[LintFinding]:
    """Open polylines (dividers, boundaries) that cross or touch themselves."""
    return _linted(views, config).self_intersection_findings()


def find_crossing_dividers(views: Sequence[ElementView], config: LintConfig) -> list[LintFinding]:
    """Pairs of dividers that intersect away from their ends (lanes cannot cross)."""
    return _linted(views, config).crossing_findings()


def find_divider_spacing(views: Sequence[ElementView], config: LintConfig) -> list[LintFinding]:
    """Neighbouring parallel dividers too close together, or with a gap that suggests a missing divider."""
    return _linted(views, config).spacing_findings()


def find_broken_boundaries(views: Sequence[ElementView], config: LintConfig) -> list[LintFinding]:
    """Two boundaries whose ends nearly meet at a window border: likely one boundary cut by the tiling."""
    return _linted(views, config).broken_boundary_findings()


def find_bad_crosswalks(views: Sequence[ElementView], config: LintConfig) -> list[LintFinding]:
    """Crosswalk polygons that are not closed (first != last) or not simple."""
    return _linted(views, config).crosswalk_findings()


def lint(
    elements: Iterable["MapElement | ElementView"],
    *,
    config: LintConfig = LintConfig(),  # noqa: B008 - frozen, so a shared default is safe
    region: Polygon | None = None,
) -> list[LintFinding]:
    """Run every lint rule over a site's elements; `region` is the site/tile outline, where ends may stop."""
    state = _linted(elements, config, region)
    findings = state.findings()
    logger.debug("lint: %d findings over %d elements", len(findings), len(state.views))
    return findings
