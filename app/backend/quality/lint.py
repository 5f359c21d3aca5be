"""Map lint: geometric plausibility checks on a site's map elements, run on save and on demand.

Pure functions over element views (id, class, (N, 2) site-metre points), so the backend can call them with
`MapElement`s from the database or with raw payloads. Neighbour search uses shapely's STRtree, so a site of
thousands of elements lints in well under a second.
"""

import logging
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
import shapely
from shapely.geometry import LinearRing, LineString, Point, Polygon
from shapely.geometry.base import BaseGeometry

from annotations.geometry import is_closed
from annotations.schema import MapElement

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

    @property
    def line(self) -> LineString:
        """The element as a shapely line (a crosswalk's ring as a line)."""
        return LineString(self.points)

    @property
    def ends(self) -> tuple[np.ndarray, np.ndarray]:
        """First and last points."""
        return self.points[0], self.points[-1]


def _geometry_array(geometries: list) -> np.ndarray:
    """Geometries as the object array STRtree.query wants (a plain empty list would be a float array)."""
    return np.array(geometries, dtype=object)


def _xy(geometry: BaseGeometry) -> tuple[float, float]:
    """A representative (x, y) of a geometry as plain floats."""
    point = geometry if isinstance(geometry, Point) else geometry.representative_point()
    return (float(point.x), float(point.y))


def _of_class(views: Sequence[ElementView], cls: str) -> list[ElementView]:
    """The views of one class, in order."""
    return [view for view in views if view.cls == cls]


def _anchor_geometry(view: ElementView) -> BaseGeometry:
    """What a divider end may attach to on this element: a crosswalk's area or a boundary's line."""
    if view.cls == "ped_crossing" and len(view.points) >= 4 and is_closed(view.points):
        polygon = Polygon(view.points)
        if polygon.is_valid:
            return polygon
    return view.line


def _is_dangling(
    view: ElementView,
    end: np.ndarray,
    views: Sequence[ElementView],
    end_tree: shapely.STRtree,
    end_owner: np.ndarray,
    anchor_tree: shapely.STRtree,
    region_border: BaseGeometry | None,
    config: LintConfig,
) -> bool:
    """Whether one divider end is far from other ends, boundaries, crosswalks and the region border."""
    point = Point(end)
    near_ends = end_tree.query(point, predicate="dwithin", distance=config.end_connect_m)
    if any(views[end_owner[k]].id != view.id for k in near_ends):
        return False
    if len(anchor_tree.query(point, predicate="dwithin", distance=config.end_connect_m)):
        return False
    return region_border is None or point.distance(region_border) > config.end_connect_m


def find_dangling_divider_ends(
    views: Sequence[ElementView], config: LintConfig, region: Polygon | None = None
) -> list[LintFinding]:
    """Divider ends that stop in the open: not near another element's end, a boundary, a crosswalk or the border."""
    ends: list[Point] = []
    owners: list[int] = []
    for index, view in enumerate(views):
        if view.cls != "ped_crossing":
            ends.extend(Point(end) for end in view.ends)
            owners.extend([index, index])
    end_tree = shapely.STRtree(ends)
    anchors = [_anchor_geometry(v) for v in views if v.cls in ("boundary", "ped_crossing")]
    anchor_tree = shapely.STRtree(anchors)
    region_border = None if region is None else region.exterior
    owner_array = np.asarray(owners, dtype=int)
    findings = []
    for view in _of_class(views, "divider"):
        for which, end in zip(("start", "end"), view.ends, strict=True):
            if _is_dangling(view, end, views, end_tree, owner_array, anchor_tree, region_border, config):
                findings.append(
                    LintFinding(
                        code="dangling_divider_end",
                        severity="warning",
                        element_ids=(view.id,),
                        location_xy=(float(end[0]), float(end[1])),
                        message=f"divider {view.id!r}: its {which} is more than {config.end_connect_m} m from any other element",
                    )
                )
    return findings


def _self_crossing_location(line: LineString) -> tuple[float, float]:
    """Where a non-simple line meets itself: a node of the noded line passed more than once."""
    noded = shapely.node(line)
    counts: dict[tuple[float, float], int] = {}
    for part in getattr(noded, "geoms", [noded]):
        coords = np.asarray(part.coords)
        for xy in (coords[0], coords[-1]):
            key = (round(float(xy[0]), 9), round(float(xy[1]), 9))
            counts[key] = counts.get(key, 0) + 1
    crossings = [key for key, count in counts.items() if count >= 3]
    return crossings[0] if crossings else _xy(line)


def find_self_intersections(views: Sequence[ElementView], config: LintConfig) -> list[LintFinding]:
    """Open polylines (dividers, boundaries) that cross or touch themselves."""
    findings = []
    for view in views:
        if view.cls == "ped_crossing":
            continue  # rings are checked by find_bad_crosswalks
        line = view.line
        if not line.is_simple:
            findings.append(
                LintFinding(
                    code="self_intersection",
                    severity="error",
                    element_ids=(view.id,),
                    location_xy=_self_crossing_location(line),
                    message=f"{view.cls} {view.id!r} crosses itself",
                )
            )
    return findings


def find_crossing_dividers(views: Sequence[ElementView], config: LintConfig) -> list[LintFinding]:
    """Pairs of dividers that intersect away from their ends (lanes cannot cross)."""
    dividers = _of_class(views, "divider")
    lines = [view.line for view in dividers]
    tree = shapely.STRtree(lines)
    pairs = tree.query(_geometry_array(lines), predicate="intersects")
    findings = []
    for i, j in zip(pairs[0], pairs[1], strict=True):
        if i >= j:
            continue
        ends = shapely.MultiPoint([*dividers[i].ends, *dividers[j].ends]).buffer(config.end_tolerance_m)
        away = lines[i].intersection(lines[j]).difference(ends)
        if away.is_empty:
            continue
        findings.append(
            LintFinding(
                code="crossing_dividers",
                severity="error",
                element_ids=(dividers[i].id, dividers[j].id),
                location_xy=_xy(away),
                message=f"dividers {dividers[i].id!r} and {dividers[j].id!r} cross",
            )
        )
    return findings


def _directions(line: LineString, stations: np.ndarray, step_m: float = 0.5) -> np.ndarray:
    """Unit tangents of a line at arc-length stations, by central differences."""
    ahead = shapely.get_coordinates(shapely.line_interpolate_point(line, stations + step_m))
    behind = shapely.get_coordinates(shapely.line_interpolate_point(line, stations - step_m))
    tangents = ahead - behind
    return tangents / np.maximum(np.linalg.norm(tangents, axis=1, keepdims=True), 1e-12)


def _parallel_offsets(
    first: LineString, second: LineString, config: LintConfig
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Distances from samples inside `first` to `second` where the two run roughly parallel, side by side.

    Returns the distances, the sample points and their nearest points on `second`; samples whose nearest point
    is an end of `second` (no side-by-side overlap) or whose directions differ too much are dropped.
    """
    count = max(int(first.length / config.spacing_sample_m), 1)
    stations = (np.arange(count) + 0.5) * first.length / count
    samples = shapely.points(shapely.get_coordinates(shapely.line_interpolate_point(first, stations)))
    on_second = shapely.line_locate_point(second, samples)
    nearest = shapely.get_coordinates(shapely.line_interpolate_point(second, on_second))
    sample_xy = shapely.get_coordinates(samples)
    distances = np.linalg.norm(sample_xy - nearest, axis=1)
    cos_angle = np.abs(np.sum(_directions(first, stations) * _directions(second, on_second), axis=1))
    inside = (on_second > 1e-6) & (on_second < second.length - 1e-6)
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


def find_divider_spacing(views: Sequence[ElementView], config: LintConfig) -> list[LintFinding]:
    """Neighbouring parallel dividers too close together, or with a gap that suggests a missing divider."""
    dividers = _of_class(views, "divider")
    lines = [view.line for view in dividers]
    tree = shapely.STRtree(lines)
    pairs = tree.query(_geometry_array(lines), predicate="dwithin", distance=config.spacing_search_m)
    findings = []
    for i, j in zip(pairs[0], pairs[1], strict=True):
        if i >= j:
            continue
        distances, sample_xy, nearest = _parallel_offsets(lines[i], lines[j], config)
        if len(distances) < config.min_overlap_samples:
            continue
        spacing_m = float(np.median(distances))
        problem = _spacing_problem(spacing_m, config)
        if problem is None:
            continue
        k = int(np.argmin(np.abs(distances - spacing_m)))
        across = LineString([sample_xy[k], nearest[k]])
        between = [m for m in tree.query(across, predicate="intersects") if m not in (i, j)]
        if between:
            continue  # another divider lies between them: they are not neighbours
        code, detail = problem
        findings.append(
            LintFinding(
                code=code,
                severity="warning",
                element_ids=(dividers[i].id, dividers[j].id),
                location_xy=_xy(across.centroid),
                message=f"dividers {dividers[i].id!r} and {dividers[j].id!r} are {detail}",
            )
        )
    return findings


def find_bad_crosswalks(views: Sequence[ElementView], config: LintConfig) -> list[LintFinding]:
    """Crosswalk polygons that are not closed (first != last) or not simple."""
    findings = []
    for view in _of_class(views, "ped_crossing"):
        points = view.points
        if not is_closed(points):
            code, message = "crosswalk_not_closed", "first point != last point"
        elif len(points) < 4 or not LinearRing(points).is_simple or not Polygon(points).is_valid:
            code, message = "crosswalk_not_simple", "polygon crosses itself or has no area"
        else:
            continue
        findings.append(
            LintFinding(
                code=code,
                severity="error",
                element_ids=(view.id,),
                location_xy=(float(points[0][0]), float(points[0][1])),
                message=f"crosswalk {view.id!r}: {message}",
            )
        )
    return findings


def _near_window_border(xy: np.ndarray, config: LintConfig) -> bool:
    """Whether a point lies within border_tolerance_m of a window border line (x or y)."""
    if config.window_size_m is None:
        return False
    offset = (xy - np.asarray(config.window_origin_xy)) / config.window_size_m
    distance_m = np.abs(offset - np.round(offset)) * config.window_size_m
    return bool((distance_m <= config.border_tolerance_m).any())


def find_broken_boundaries(views: Sequence[ElementView], config: LintConfig) -> list[LintFinding]:
    """Two boundaries whose ends nearly meet at a window border: likely one boundary cut by the tiling."""
    if config.window_size_m is None:
        return []
    boundaries = _of_class(views, "boundary")
    ends = [end for view in boundaries for end in view.ends]
    tree = shapely.STRtree([Point(end) for end in ends])
    pairs = tree.query(
        _geometry_array([Point(end) for end in ends]), predicate="dwithin", distance=config.break_gap_m
    )
    findings = []
    for a, b in zip(pairs[0], pairs[1], strict=True):
        first, second = boundaries[a // 2], boundaries[b // 2]
        if a >= b or first.id == second.id:
            continue
        middle = (ends[a] + ends[b]) / 2.0
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


def lint(
    elements: Iterable["MapElement | ElementView"],
    *,
    config: LintConfig = LintConfig(),  # noqa: B008 - frozen, so a shared default is safe
    region: Polygon | None = None,
) -> list[LintFinding]:
    """Run every lint rule over a site's elements; `region` is the site/tile outline, where ends may stop."""
    views = [ElementView.of(element) for element in elements]
    findings = [
        *find_dangling_divider_ends(views, config, region),
        *find_self_intersections(views, config),
        *find_crossing_dividers(views, config),
        *find_divider_spacing(views, config),
        *find_broken_boundaries(views, config),
        *find_bad_crosswalks(views, config),
    ]
    logger.debug("lint: %d findings over %d elements", len(findings), len(views))
    return findings
