"""Polyline and polygon geometry for map elements: validation, resampling, simplification, clipping.

Points are (N, 2) or (N, 3) arrays in metres; a polygon (a crosswalk) is a closed ring whose first and last
points are equal. Lengths and spacings are measured in the plane (x, y); z is interpolated along.
"""

import logging
from typing import NamedTuple

import numpy as np
import shapely
from numpy.typing import ArrayLike
from shapely.geometry import LinearRing, LineString, Polygon, box
from shapely.geometry.base import BaseGeometry

logger = logging.getLogger(__name__)

CLOSE_TOLERANCE_M = 1e-9
"""How far apart a ring's first and last points may be and still count as closed."""


class Box(NamedTuple):
    """An axis-aligned region in metres; unpacks as `clip_to_box(points, *box)`."""

    xmin: float
    xmax: float
    ymin: float
    ymax: float


MAPTR_RANGE = Box(xmin=-30.0, xmax=30.0, ymin=-15.0, ymax=15.0)
"""MapTR's perception range in the ego frame: x in [-30, 30] m forward, y in [-15, 15] m left."""


def as_points(points: ArrayLike, *, field: str = "points", dims: int | None = None) -> np.ndarray:
    """`points` as a float (N, 2) or (N, 3) array; ValueError naming `field` on any other shape."""
    array = np.asarray(points, dtype=float)
    if array.ndim != 2 or array.shape[1] not in (2, 3):
        raise ValueError(f"{field}: expected a list of [x, y] or [x, y, z] points, got shape {array.shape}")
    if dims is not None and array.shape[1] != dims:
        raise ValueError(f"{field}: expected {dims} coordinates per point, got {array.shape[1]}")
    return array


def is_closed(points: np.ndarray) -> bool:
    """Whether the first and last points coincide (within CLOSE_TOLERANCE_M)."""
    return len(points) >= 2 and bool(np.all(np.abs(points[0] - points[-1]) <= CLOSE_TOLERANCE_M))


def validate_geometry(
    points: ArrayLike, *, closed: bool, field: str = "points", dims: int | None = None
) -> np.ndarray:
    """Check a polyline (or, if `closed`, a polygon ring) and return it as an array; ValueError naming `field`."""
    array = _finite_points(points, field=field, dims=dims)
    if _planar_length(array) <= 0.0:
        raise ValueError(f"{field}: all points coincide (zero length)")
    if closed:
        _validate_ring(array, field)
    return array


def _finite_points(points: ArrayLike, *, field: str = "points", dims: int | None = None) -> np.ndarray:
    """At least 2 finite points as an array (they may coincide); ValueError naming `field` otherwise."""
    array = as_points(points, field=field, dims=dims)
    if len(array) < 2:
        raise ValueError(f"{field}: needs at least 2 points, got {len(array)}")
    bad = np.flatnonzero(~np.isfinite(array).all(axis=1))
    if bad.size:
        raise ValueError(f"{field}: point {int(bad[0])} is not finite: {array[bad[0]].tolist()}")
    return array


def _validate_ring(array: np.ndarray, field: str) -> None:
    """Check that a polygon ring is closed, has a non-zero area and does not cross itself."""
    if not is_closed(array):
        raise ValueError(
            f"{field}: polygon is not closed: first point {array[0].tolist()} != last point {array[-1].tolist()}"
        )
    if len(array) < 4:
        raise ValueError(
            f"{field}: polygon needs at least 4 points (3 corners + the closing point), got {len(array)}"
        )
    polygon = Polygon(array[:, :2])
    if not LinearRing(array[:, :2]).is_simple:
        raise ValueError(f"{field}: polygon crosses itself (not simple): {shapely.is_valid_reason(polygon)}")
    if polygon.area <= 0.0:
        raise ValueError(f"{field}: polygon has zero area")
    if not polygon.is_valid:
        raise ValueError(f"{field}: polygon is not simple: {shapely.is_valid_reason(polygon)}")


def _planar_length(array: np.ndarray) -> float:
    """Length of the polyline in the (x, y) plane."""
    return float(np.linalg.norm(np.diff(array[:, :2], axis=0), axis=1).sum())


def arc_lengths(array: np.ndarray) -> np.ndarray:
    """Cumulative planar arc length at each vertex, starting at 0."""
    steps = np.linalg.norm(np.diff(array[:, :2], axis=0), axis=1)
    return np.concatenate([[0.0], np.cumsum(steps)])


def _interpolate(array: np.ndarray, stations: np.ndarray) -> np.ndarray:
    """Points at the given arc-length stations, every coordinate interpolated linearly."""
    arc = arc_lengths(array)
    keep = np.concatenate([[True], np.diff(arc) > 0])  # np.interp needs strictly increasing stations
    arc, array = arc[keep], array[keep]
    return np.stack([np.interp(stations, arc, array[:, k]) for k in range(array.shape[1])], axis=1)


def resample_fixed(points: ArrayLike, n: int) -> np.ndarray:
    """`n` points evenly spaced by planar arc length, keeping both ends (a closed ring stays closed); a polyline
    of zero length (a degenerate prediction) gives `n` copies of its first point. The resampling of Chamfer-AP
    and VMA targets and merging too (MapTR resamples vectors to a fixed count the same way)."""
    if n < 2:
        raise ValueError(f"n: need at least 2 points, got {n}")
    array = _finite_points(points)
    arc = arc_lengths(array)
    if arc[-1] <= 0.0:
        return np.repeat(array[:1], n, axis=0)
    out = _interpolate(array, np.linspace(0.0, arc[-1], n))
    out[0], out[-1] = array[0], array[-1]
    return out


def resample_spacing(points: ArrayLike, spacing_m: float) -> np.ndarray:
    """Points evenly spaced by arc length at most `spacing_m` apart, keeping both ends."""
    if not np.isfinite(spacing_m) or spacing_m <= 0:
        raise ValueError(f"spacing_m: must be a positive number of metres, got {spacing_m}")
    array = validate_geometry(points, closed=False)
    count = int(np.ceil(_planar_length(array) / spacing_m - 1e-9)) + 1
    return resample_fixed(array, max(count, 2))


def densify(points: ArrayLike, max_spacing_m: float) -> np.ndarray:
    """Insert points so that no segment is longer than `max_spacing_m`; the original vertices are kept."""
    if not np.isfinite(max_spacing_m) or max_spacing_m <= 0:
        raise ValueError(f"max_spacing_m: must be a positive number of metres, got {max_spacing_m}")
    array = validate_geometry(points, closed=False)
    pieces = [array[:1]]
    for start, end in zip(array[:-1], array[1:], strict=True):
        steps = max(int(np.ceil(np.linalg.norm(end[:2] - start[:2]) / max_spacing_m - 1e-9)), 1)
        t = np.arange(1, steps + 1)[:, None] / steps
        pieces.append(start + t * (end - start))
    out = np.concatenate(pieces)
    out[-1] = array[-1]
    return out


def simplify(points: ArrayLike, tolerance_m: float) -> np.ndarray:
    """Douglas-Peucker simplification that keeps both ends and never makes a simple line cross itself."""
    if not np.isfinite(tolerance_m) or tolerance_m < 0:
        raise ValueError(f"tolerance_m: must be a non-negative number of metres, got {tolerance_m}")
    array = validate_geometry(points, closed=False)
    if len(array) <= 2 or tolerance_m == 0:
        return array.copy()
    kept_xy = np.asarray(LineString(array[:, :2]).simplify(tolerance_m, preserve_topology=True).coords)
    return array[_match_vertices(array[:, :2], kept_xy)]


def _match_vertices(original_xy: np.ndarray, kept_xy: np.ndarray) -> list[int]:
    """Indices of the kept vertices in the original polyline, searched forward so order is preserved."""
    indices: list[int] = []
    start = 0
    for point in kept_xy:
        distances = np.linalg.norm(original_xy[start:] - point, axis=1)
        index = start + int(np.argmin(distances))
        indices.append(index)
        start = index + 1 if index + 1 < len(original_xy) else index
    indices[0], indices[-1] = 0, len(original_xy) - 1
    return indices


def clip_to_box(
    points: ArrayLike, xmin: float, xmax: float, ymin: float, ymax: float, *, closed: bool = False
) -> list[np.ndarray]:
    """The parts of a polyline (or polygon, if `closed`) inside the box; z is interpolated at the cuts."""
    if not (xmin < xmax and ymin < ymax):
        raise ValueError(
            f"clip box: need xmin < xmax and ymin < ymax, got x [{xmin}, {xmax}], y [{ymin}, {ymax}]"
        )
    array = validate_geometry(points, closed=closed)
    region = box(xmin, ymin, xmax, ymax)
    if closed:
        clipped = Polygon(array).intersection(region)
        return [np.asarray(part.exterior.coords) for part in _parts(clipped, Polygon) if part.area > 0]
    clipped = LineString(array).intersection(region)
    return [np.asarray(part.coords) for part in _parts(clipped, LineString) if part.length > 0]


def _parts(geometry: BaseGeometry, kind: type[BaseGeometry]) -> list[BaseGeometry]:
    """The pieces of type `kind` in a (possibly multi-part or mixed) shapely result, in GEOS order."""
    if geometry.is_empty:
        return []
    if isinstance(geometry, kind):
        return [geometry]
    return [part for part in getattr(geometry, "geoms", []) if isinstance(part, kind)]
