"""A scene's labels cut from the site's annotation (CAMAv2: annotate the site once, then cut each scene from it).

A scene's observed range is the union of its cameras' trajectories (one per camera channel, time order) buffered
by `observed_radius_m`, intersected with the map square. Each element is clipped at that boundary (shapely): an
element inside it is kept unchanged; a divider or boundary becomes one or more pieces (pieces with fewer than 2
points or shorter than `MIN_PIECE_LENGTH_M` dropped); a crosswalk polygon is intersected as a polygon (pieces
under `MIN_PIECE_AREA_M2` dropped; a piece's holes, possible only where the range itself has one, are not kept:
the release stores a crosswalk as one ring). Ids stay traceable: one piece keeps the element id, several get
`<id>#1`, `<id>#2`, ... in the order shapely returns them (along the line for a polyline).
"""

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np
import shapely
from shapely.geometry import LineString, Point, Polygon
from shapely.geometry.base import BaseGeometry

from annotations.schema import AnnotationSet, ElementClass

DEFAULT_OBSERVED_RADIUS_M = 21.0
"""Default radius of a scene's observed range: the surface stage's ray range (`SurfaceConfig.max_range_m`, 21 m):
the raster (and so the annotation) holds nothing a camera did not see within it."""
MIN_PIECE_LENGTH_M = 0.5
"""Shorter pieces of a clipped polyline are dropped."""
MIN_PIECE_AREA_M2 = 0.25
"""Smaller pieces of a clipped crosswalk are dropped."""
PIECE_SEPARATOR = "#"


@dataclass(frozen=True, eq=False)
class Piece:
    """One instance of a cut: (a piece of) an element in site metres."""

    instance_id: str
    """The element id, with `#k` appended when the element was split into several pieces."""
    element_id: str
    cls: ElementClass
    xy: np.ndarray
    """(N, 2) site metres; a crosswalk's ring is closed."""
    track_id: int
    """The element's index in the annotation set (the same in every scene it appears in)."""


def observed_range(trajectories: Sequence[np.ndarray], radius_m: float, square: Polygon) -> BaseGeometry:
    """The union of the (N, 2) trajectories buffered by `radius_m`, within `square` (all in one frame)."""
    if not (np.isfinite(radius_m) and radius_m > 0):
        raise ValueError(f"observed_radius_m: expected a finite value > 0, got {radius_m}")
    if not trajectories:
        raise ValueError("observed range: no camera positions")
    shapes = [
        Point(track[0]) if len(track) == 1 else LineString(track)
        for track in (np.asarray(t, dtype=float)[:, :2] for t in trajectories)
    ]
    return shapely.unary_union([shape.buffer(radius_m) for shape in shapes]).intersection(square)


def cut_elements(annotations: AnnotationSet, region: BaseGeometry) -> list[Piece]:
    """Every element's pieces within `region` (site metres), in element order."""
    shapely.prepare(region)
    pieces: list[Piece] = []
    for track_id, element in enumerate(annotations.elements):
        xy = element.xy()
        shape: BaseGeometry = Polygon(xy) if element.closed else LineString(xy)
        if region.covers(shape):
            parts = [xy]
        elif not region.intersects(shape):
            continue
        elif element.closed:
            parts = _polygon_parts(shape.intersection(region))
        else:
            parts = _line_parts(shape.intersection(region))
        for index, part in enumerate(parts, start=1):
            piece_id = element.id if len(parts) == 1 else f"{element.id}{PIECE_SEPARATOR}{index}"
            pieces.append(Piece(piece_id, element.id, element.cls, part, track_id))
    return pieces


def _flatten(geometry: BaseGeometry) -> Iterable[BaseGeometry]:
    """The simple geometries inside a (multi-part or collection) geometry."""
    if hasattr(geometry, "geoms"):
        for part in geometry.geoms:
            yield from _flatten(part)
    elif not geometry.is_empty:
        yield geometry


def _line_parts(geometry: BaseGeometry) -> list[np.ndarray]:
    """The pieces of a clipped polyline, contiguous parts merged, short ones dropped."""
    lines = [part for part in _flatten(geometry) if isinstance(part, LineString)]
    if len(lines) > 1:
        lines = [p for p in _flatten(shapely.line_merge(shapely.MultiLineString(lines), directed=True))]
    return [
        np.asarray(line.coords, dtype=float)[:, :2]
        for line in lines
        if isinstance(line, LineString) and len(line.coords) >= 2 and line.length >= MIN_PIECE_LENGTH_M
    ]


def _polygon_parts(geometry: BaseGeometry) -> list[np.ndarray]:
    """The exterior rings (closed) of a clipped crosswalk's pieces, small ones dropped."""
    return [
        np.asarray(part.exterior.coords, dtype=float)[:, :2]
        for part in _flatten(geometry)
        if isinstance(part, Polygon) and part.area >= MIN_PIECE_AREA_M2
    ]
