"""Map vectors as the VMA proposers and their training use them: class, global (x, y) points, confidence.

A `ped_crossing` is a closed ring (first point == last point); dividers and boundaries are open polylines.
Conversions to and from the evaluation's `MapVector`, the annotation model's `MapElement` and clipping to
axis-aligned boxes live here so every other module deals in `Vector` only.
"""

import logging
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from shapely.geometry import LineString, Polygon, box

from annotations import AnnotationSet, Georeference, MapElement
from annotations.schema import ELEMENT_CLASSES, POLYGON_CLASSES
from cama_pipeline.evaluate.chamfer_ap import MapVector
from cama_pipeline.evaluate.inputs import load_vector_map

logger = logging.getLogger(__name__)

CLASSES: tuple[str, ...] = ELEMENT_CLASSES
"""Vector classes, in the order of the model's class scores."""


@dataclass(frozen=True, eq=False)
class Vector:
    """One map vector in global metres with a confidence in [0, 1] (1 for ground truth and human labels)."""

    cls: str
    points: np.ndarray
    """(N, 2) global metres; closed classes repeat the first point at the end."""
    score: float = 1.0

    def __post_init__(self) -> None:
        if self.cls not in CLASSES:
            raise ValueError(f"Vector: unknown class {self.cls!r}, expected one of {CLASSES}")
        points = np.asarray(self.points, dtype=np.float64)
        if points.ndim != 2 or points.shape[0] < 2 or points.shape[1] < 2 or not np.isfinite(points).all():
            raise ValueError(f"Vector: points must be finite (N, 2) with N >= 2, got shape {points.shape}")
        object.__setattr__(self, "points", points[:, :2])

    @property
    def closed(self) -> bool:
        """Whether this vector is a polygon ring."""
        return self.cls in POLYGON_CLASSES

    def length_m(self) -> float:
        """Planar length (perimeter for rings)."""
        return float(np.linalg.norm(np.diff(self.points, axis=0), axis=1).sum())

    def to_map_vector(self) -> MapVector:
        """As the Chamfer-AP evaluation's vector."""
        return MapVector(self.cls, self.points, self.score)


def read_vectors(path: Path) -> list[Vector]:
    """Ground-truth vectors of a vector-map JSON file (errors name the file and element)."""
    out = []
    for element in load_vector_map(path):
        points = np.asarray(element.points)[:, :2]
        if element.cls in POLYGON_CLASSES and not np.allclose(points[0], points[-1]):
            points = np.vstack([points, points[:1]])
        out.append(Vector(element.cls, points))
    return out


def clip_vectors(
    vectors: Iterable[Vector], bounds: tuple[float, float, float, float], min_length_m: float
) -> list[Vector]:
    """The parts of each vector inside (xmin, xmax, ymin, ymax) at least `min_length_m` long (rings stay rings)."""
    xmin, xmax, ymin, ymax = bounds
    region = box(xmin, ymin, xmax, ymax)
    out = []
    for vector in vectors:
        if vector.closed:
            ring = Polygon(vector.points)
            if not ring.is_valid:
                ring = ring.buffer(0)
            pieces = _parts(ring.intersection(region), Polygon)
            coords = [np.asarray(p.exterior.coords) for p in pieces]
        else:
            pieces = _parts(LineString(vector.points).intersection(region), LineString)
            coords = [np.asarray(p.coords) for p in pieces]
        for c in coords:
            piece = Vector(vector.cls, c, vector.score)
            if piece.length_m() >= min_length_m:
                out.append(piece)
    return out


def _parts(geometry: object, kind: type) -> list:
    """Pieces of type `kind` of a shapely result (single, multi-part or collection)."""
    if getattr(geometry, "is_empty", True):
        return []
    if isinstance(geometry, kind):
        return [geometry]
    return [g for g in getattr(geometry, "geoms", []) if isinstance(g, kind)]


def vectors_from_annotations(annotations: AnnotationSet, states: Sequence[str]) -> list[Vector]:
    """Vectors (global metres) of the elements whose review state is in `states`."""
    ox, oy = annotations.georeference.site_origin_xy
    return [
        Vector(e.cls, e.xy()[:, :2] + np.array([ox, oy]), 1.0 if e.confidence is None else e.confidence)
        for e in annotations.elements
        if e.review_state in states
    ]


def simple_geometry(vector: Vector) -> Vector | None:
    """The vector made acceptable to the annotation model: a crossing ring that crosses itself becomes its
    convex hull; consecutive duplicate points are dropped; None when nothing of positive size is left."""
    points = vector.points[np.r_[True, np.any(np.diff(vector.points, axis=0) != 0, axis=1)]]
    if vector.closed:
        ring = Polygon(points)
        if not ring.is_valid:
            ring = ring.convex_hull
        if not isinstance(ring, Polygon) or ring.area <= 0:
            return None
        return Vector(vector.cls, np.asarray(ring.exterior.coords), vector.score)
    if len(points) < 2:
        return None
    return Vector(vector.cls, points, vector.score)


def proposals_as_annotations(
    vectors: Sequence[Vector], georeference: Georeference, site_id: str, author: str
) -> AnnotationSet:
    """Proposals as an AnnotationSet (site metres, source 'proposal', confidence set), ids `vma-00000`..."""
    origin = np.array(georeference.site_origin_xy)
    elements = []
    for k, vector in enumerate(v for v in (simple_geometry(v) for v in vectors) if v is not None):
        points = vector.points - origin
        elements.append(
            MapElement(
                id=f"vma-{k:05d}",
                cls=vector.cls,  # type: ignore[arg-type]  # checked by Vector
                points_2d=[(float(x), float(y)) for x, y in points],
                source="proposal",
                confidence=float(np.clip(vector.score, 0.0, 1.0)),
                author=author,
            )
        )
    return AnnotationSet(site_id=site_id, georeference=georeference, elements=elements)
