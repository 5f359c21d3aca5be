"""Map lint rules, one element or one pair of elements at a time (`app.backend.quality.lint` runs them over a
site, and again only around the elements that changed).

Pure functions over element views (id, class, (N, 2) site-metre points), so the backend can call them with
`MapElement`s from the database or with raw payloads. Along-line sampling, projection and segment crossings go
through `Polyline` (arc length and a chunked segment index), so their cost grows with the samples and the
crossings, not with samples x vertices.
"""

import logging
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cached_property
from typing import Literal

import numpy as np
import shapely
from shapely.geometry import LinearRing, LineString, Point, Polygon
from shapely.geometry.base import BaseGeometry

from annotations.geometry import is_closed
from annotations.schema import MapElement
from app.backend.quality.polyline import Polyline, as_geometry_array

logger = logging.getLogger(__name__)

Severity = Literal["error", "warning"]


@dataclass(frozen=True)
class LintConfig:
    """Thresholds of the lint rules, in metres and degrees; validated on creation."""

    end_connect_m: float = 1.5
    """A divider end this close to another element's end, a boundary, a crosswalk or the region border is not dangling."""
    end_tolerance_m: float = 0.5
    """Two dividers meeting within this distance of an end do not count as crossing."""
    min_spacing_m: float = 2.5
    """Neighbouring parallel dividers closer than this are implausibly narrow."""
    missing_gap_m: tuple[float, float] = (4.5, 6.0)
    """A spacing in this [low, high] range suggests a missing divider between two dividers."""
    spacing_search_m: float = 7.0
    """How far to look for a neighbouring divider; above missing_gap_m's high end."""
    parallel_max_angle_deg: float = 20.0
    """Two dividers count as roughly parallel where their directions differ by at most this."""
    spacing_sample_m: float = 2.0
    """Spacing between samples along a divider when measuring spacing."""
    min_overlap_samples: int = 3
    """A pair of dividers is compared only where at least this many samples see the other in parallel."""
    window_size_m: float | None = None
    """Size of the tiles/windows that proposals were made in; None skips the broken-boundary rule."""
    window_origin_xy: tuple[float, float] = (0.0, 0.0)
    """Site coordinates of a window corner; borders lie at origin + k * window_size_m."""
    break_gap_m: float = 1.0
    """Two boundary ends closer than this (near a window border) look like one boundary broken in two."""
    border_tolerance_m: float = 1.0
    """How close to a window border a break must be."""

    def __post_init__(self) -> None:
        """Reject non-positive distances and an inverted missing-gap range."""
        for name in (
            "end_connect_m",
            "end_tolerance_m",
            "min_spacing_m",
            "spacing_search_m",
            "spacing_sample_m",
        ):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name}: must be positive, got {getattr(self, name)}")
        for name in ("break_gap_m", "border_tolerance_m"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name}: must be positive, got {getattr(self, name)}")
        low, high = self.missing_gap_m
        if not 0 < low <= high:
            raise ValueError(f"missing_gap_m: expected 0 < low <= high, got {self.missing_gap_m}")
        if self.window_size_m is not None and not self.window_size_m > 0:
            raise ValueError(f"window_size_m: must be positive or None, got {self.window_size_m}")
        if not 0 < self.parallel_max_angle_deg < 90:
            raise ValueError(f"parallel_max_angle_deg: must be in (0, 90), got {self.parallel_max_angle_deg}")
        if self.min_overlap_samples < 1:
            raise ValueError(f"min_overlap_samples: must be >= 1, got {self.min_overlap_samples}")


@dataclass(frozen=True)
class LintFinding:
    """One lint problem: a stable code, its severity, the elements involved and where to look."""

    code: str
    severity: Severity
    element_ids: tuple[str, ...]
    location_xy: tuple[float, float]
    message: str


@dataclass(frozen=True)
class ElementView:
    """The geometry the lint needs from a map element: id, class and (N, 2) site-metre points."""

    id: str
    cls: str
    points: np.ndarray = field(repr=False)

    @classmethod
    def of(cls, element: "MapElement | ElementView") -> "ElementView":
        """A view of a `MapElement` (or the view itself); ValueError on malformed points."""
        if isinstance(element, ElementView):
            return element
        return cls(id=element.id, cls=element.cls, points=element.xy()[:, :2])

    def __post_init__(self) -> None:
        """Check the point array's shape and finiteness."""
        points = np.asarray(self.points, dtype=float)
        if points.ndim != 2 or points.shape[1] < 2 or len(points) < 2 or not np.isfinite(points).all():
            raise ValueError(f"element {self.id!r}: points must be >= 2 finite [x, y] points")
        object.__setattr__(self, "points", points[:, :2])

    @cached_property
    def line(self) -> LineString:
        """The element as a shapely line (a crosswalk's ring as a line)."""
        return LineString(self.points)

    @cached_property
    def polyline(self) -> Polyline:
        """The element's points with arc length and a segment index, for sampling and crossings."""
        return Polyline(self.points)

    @cached_property
    def anchor(self) -> BaseGeometry:
        """What a divider end may attach to on this element: a crosswalk's area or a boundary's line."""
        if self.cls == "ped_crossing" and len(self.points) >= 4 and is_closed(self.points):
            polygon = Polygon(self.points)
            if polygon.is_valid:
                return polygon
        return self.line

    @cached_property
    def bounds(self) -> tuple[float, float, float, float]:
        """xmin, ymin, xmax, ymax."""
        (xmin, ymin), (xmax, ymax) = self.points.min(axis=0), self.points.max(axis=0)
        return (float(xmin), float(ymin), float(xmax), float(ymax))

    @property
    def ends(self) -> tuple[np.ndarray, np.ndarray]:
        """First and last points."""
        return self.points[0], self.points[-1]


def _xy(geometry: BaseGeometry) -> tuple[float, float]:
    """A representative (x, y) of a geometry as plain floats."""
    point = geometry if isinstance(geometry, Point) else geometry.representative_point()
    return (float(point.x), float(point.y))


def _interior_point(points: np.ndarray) -> tuple[float, float]:
    """GEOS's interior point of a multipoint (what `representative_point` gives): the first point nearest the
    centroid, with the centroid summed in order as GEOS sums it."""
    centroid = np.add.accumulate(points, axis=0)[-1] / len(points)
    offset = points - centroid
    k = int(np.argmin(np.sqrt(offset[:, 0] * offset[:, 0] + offset[:, 1] * offset[:, 1])))
    return (float(points[k, 0]), float(points[k, 1]))


def self_intersection_of(view: ElementView) -> LintFinding | None:
    """An open polyline (divider, boundary) that crosses or touches itself, located where it first meets itself
    again along its length; crosswalk rings are checked by `bad_crosswalk_of`."""
    if view.cls == "ped_crossing" or view.line.is_simple:
        return None
    return LintFinding(
        code="self_intersection",
        severity="error",
        element_ids=(view.id,),
        location_xy=view.polyline.first_self_crossing() or _xy(view.line),
        message=f"{view.cls} {view.id!r} crosses itself",
    )


def bad_crosswalk_of(view: ElementView) -> LintFinding | None:
    """A crosswalk polygon that is not closed (first != last) or not simple."""
    if view.cls != "ped_crossing":
        return None
    points = view.points
    if not is_closed(points):
        code, message = "crosswalk_not_closed", "first point != last point"
    elif len(points) < 4 or not LinearRing(points).is_simple or not Polygon(points).is_valid:
        code, message = "crosswalk_not_simple", "polygon crosses itself or has no area"
    else:
        return None
    return LintFinding(
        code=code,
        severity="error",
        element_ids=(view.id,),
        location_xy=(float(points[0][0]), float(points[0][1])),
        message=f"crosswalk {view.id!r}: {message}",
    )


def crossing_of(first: ElementView, second: ElementView, config: LintConfig) -> LintFinding | None:
    """Two dividers that intersect away from their ends (lanes cannot cross), located as the overlay of the two
    lines would be: the crossing nearest the centroid of the crossings away from the ends."""
    _mine, _theirs, meet = first.polyline.crossings_with(second.polyline)
    if not len(meet):
        return None
    ends = shapely.MultiPoint([*first.ends, *second.ends]).buffer(config.end_tolerance_m)
    if (shapely.get_type_id(meet) != 0).any():  # segments overlap: the overlay of the whole pair (rare)
        away = first.line.intersection(second.line).difference(ends)
        if away.is_empty:
            return None
        location = _xy(away)
    else:
        points = np.unique(shapely.get_coordinates(meet), axis=0)  # the overlay's nodes, sorted by x then y
        points = points[~shapely.intersects(ends, shapely.points(points))]
        if not len(points):
            return None
        location = _interior_point(points)
    return LintFinding(
        code="crossing_dividers",
        severity="error",
        element_ids=(first.id, second.id),
        location_xy=location,
        message=f"dividers {first.id!r} and {second.id!r} cross",
    )


def _directions(line: Polyline, stations: np.ndarray, step_m: float = 0.5) -> np.ndarray:
    """Unit tangents of a line at arc-length stations, by central differences."""
    tangents = line.interpolate(stations + step_m) - line.interpolate(stations - step_m)
    return tangents / np.maximum(np.linalg.norm(tangents, axis=1, keepdims=True), 1e-12)


def _parallel_offsets(
    first: Polyline, second: Polyline, config: LintConfig
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Distances from samples inside `first` to `second` where the two run roughly parallel, side by side.

    Returns the distances, the sample points and their nearest points on `second`; samples whose nearest point
    is an end of `second` (no side-by-side overlap), is farther than `spacing_search_m`, or whose directions
    differ too much are dropped.
    """
    count = max(int(first.length_m / config.spacing_sample_m), 1)
    stations = (np.arange(count) + 0.5) * first.length_m / count
    sample_xy = first.interpolate(stations)
    on_second = second.locate(sample_xy, config.spacing_search_m * (1.0 + 1e-9))
    found = ~np.isnan(on_second)
    stations, sample_xy, on_second = stations[found], sample_xy[found], on_second[found]
    nearest = second.interpolate(on_second)
    distances = np.linalg.norm(sample_xy - nearest, axis=1)
    cos_angle = np.abs(np.sum(_directions(first, stations) * _directions(second, on_second), axis=1))
    inside = (on_second > 1e-6) & (on_second < second.length_m - 1e-6)
    keep = inside & (cos_angle >= np.cos(np.radians(config.parallel_max_angle_deg)))
    keep &= distances <= config.spacing_search_m
    return distances[keep], sample_xy[keep], nearest[keep]


def _spacing_problem(spacing_m: float, config: LintConfig) -> tuple[str, str] | None:
    """The (code, message) for an implausible spacing between neighbouring dividers, or None."""
    low, high = config.missing_gap_m
    if spacing_m < config.min_spacing_m:
        return "divider_spacing_narrow", f"{spacing_m:.2f} m apart, under {config.min_spacing_m} m"
    if low <= spacing_m <= high:
        return "divider_spacing_missing", f"{spacing_m:.2f} m apart: a divider may be missing between them"
    return None


@dataclass(frozen=True)
class SpacingCandidate:
    """A spacing finding of a divider pair, to be kept only if no other divider crosses `across` (the
    representative offset between the two): a divider between them means they are not neighbours."""

    finding: LintFinding
    across: LineString


def spacing_candidate_of(
    first: ElementView, second: ElementView, config: LintConfig
) -> SpacingCandidate | None:
    """Two parallel dividers too close together, or with a gap that suggests a missing divider between them."""
    distances, sample_xy, nearest = _parallel_offsets(first.polyline, second.polyline, config)
    if len(distances) < config.min_overlap_samples:
        return None
    spacing_m = float(np.median(distances))
    problem = _spacing_problem(spacing_m, config)
    if problem is None:
        return None
    k = int(np.argmin(np.abs(distances - spacing_m)))
    across = LineString([sample_xy[k], nearest[k]])
    code, detail = problem
    finding = LintFinding(
        code=code,
        severity="warning",
        element_ids=(first.id, second.id),
        location_xy=_xy(across.centroid),
        message=f"dividers {first.id!r} and {second.id!r} are {detail}",
    )
    return SpacingCandidate(finding=finding, across=across)


def unblocked_spacing(
    candidates: Sequence[SpacingCandidate], dividers: Sequence[ElementView]
) -> list[LintFinding]:
    """The spacing findings of the candidates whose offset no other of `dividers` crosses."""
    if not candidates:
        return []
    boxes = shapely.box(*np.asarray([view.bounds for view in dividers], dtype=float).reshape(-1, 4).T)
    across = as_geometry_array([candidate.across for candidate in candidates])
    query, hit = shapely.STRtree(boxes).query(across)
    blocked: set[int] = set()
    for q, h in zip(query.tolist(), hit.tolist(), strict=True):
        if q in blocked or dividers[h].id in candidates[q].finding.element_ids:
            continue
        if dividers[h].polyline.intersects(across[q]):
            blocked.add(q)
    return [candidate.finding for k, candidate in enumerate(candidates) if k not in blocked]


def _near_window_border(xy: np.ndarray, config: LintConfig) -> bool:
    """Whether a point lies within border_tolerance_m of a window border line (x or y)."""
    if config.window_size_m is None:
        return False
    offset = (xy - np.asarray(config.window_origin_xy)) / config.window_size_m
    distance_m = np.abs(offset - np.round(offset)) * config.window_size_m
    return bool((distance_m <= config.border_tolerance_m).any())


def broken_boundaries_of(first: ElementView, second: ElementView, config: LintConfig) -> list[LintFinding]:
    """Ends of two boundaries that nearly meet at a window border: likely one boundary cut by the tiling."""
    if config.window_size_m is None:
        return []
    findings = []
    for first_end in first.ends:
        for second_end in second.ends:
            if not shapely.dwithin(Point(first_end), Point(second_end), config.break_gap_m):
                continue
            middle = (first_end + second_end) / 2.0
            if not _near_window_border(middle, config):
                continue
            findings.append(
                LintFinding(
                    code="boundary_broken_at_border",
                    severity="warning",
                    element_ids=(first.id, second.id),
                    location_xy=(float(middle[0]), float(middle[1])),
                    message=f"boundaries {first.id!r} and {second.id!r} nearly meet at a window border; merge them?",
                )
            )
    return findings


def _point_array(xy: list[np.ndarray]) -> np.ndarray:
    """Points as a geometry array (empty-safe)."""
    return shapely.points(np.asarray(xy, dtype=float).reshape(-1, 2)) if xy else as_geometry_array([])


@dataclass(frozen=True)
class EndContext:
    """What a divider end may stop at: another element's end, a boundary or crosswalk, the region border."""

    end_tree: shapely.STRtree
    end_owner: list[str]
    """Id of the element of each end in `end_tree`."""
    anchor_tree: shapely.STRtree
    region_border: BaseGeometry | None

    @classmethod
    def of(cls, views: Sequence[ElementView], region: Polygon | None) -> "EndContext":
        """The context of a site's elements (crosswalks have no ends; boundaries and crosswalks are anchors)."""
        with_ends = [view for view in views if view.cls != "ped_crossing"]
        anchors = [view.anchor for view in views if view.cls in ("boundary", "ped_crossing")]
        return cls(
            end_tree=shapely.STRtree(_point_array([end for view in with_ends for end in view.ends])),
            end_owner=[view.id for view in with_ends for _ in range(2)],
            anchor_tree=shapely.STRtree(as_geometry_array(anchors)),
            region_border=None if region is None else region.exterior,
        )


def dangling_ends_of(
    dividers: Sequence[ElementView], context: EndContext, config: LintConfig
) -> dict[str, list[LintFinding]]:
    """Per divider, its ends that stop in the open: not near another element's end, a boundary, a crosswalk or
    the region border."""
    points = _point_array([end for view in dividers for end in view.ends])
    connected = np.zeros(len(points), dtype=bool)
    query, hit = context.end_tree.query(points, predicate="dwithin", distance=config.end_connect_m)
    other = [context.end_owner[h] != dividers[q // 2].id for q, h in zip(query, hit, strict=True)]
    connected[query[np.asarray(other, dtype=bool)]] = True
    query, _hit = context.anchor_tree.query(points, predicate="dwithin", distance=config.end_connect_m)
    connected[query] = True
    if context.region_border is not None and len(points):
        connected |= shapely.distance(points, context.region_border) <= config.end_connect_m
    findings: dict[str, list[LintFinding]] = {view.id: [] for view in dividers}
    for k in np.flatnonzero(~connected).tolist():
        view, which = dividers[k // 2], ("start", "end")[k % 2]
        end = view.points[0] if k % 2 == 0 else view.points[-1]
        findings[view.id].append(
            LintFinding(
                code="dangling_divider_end",
                severity="warning",
                element_ids=(view.id,),
                location_xy=(float(end[0]), float(end[1])),
                message=f"divider {view.id!r}: its {which} is more than {config.end_connect_m} m from any other element",
            )
        )
    return findings
