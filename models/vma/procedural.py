"""Procedurally generated BEV training patches: random road layouts drawn straight into raster space.

One or two roads (straight or gently curved, 1-3 lanes each way) cross a square patch; their union's edge
is the curb (boundary vectors), lane lines are solid, dashed or double (divider vectors, the line's centre),
and crossings get zebra stripes (ped_crossing rectangles). Geometry is built with shapely in patch pixels
and rasterised with OpenCV at 4x sub-pixel precision, so labels and vectors agree exactly.
"""

import cv2
import numpy as np
from shapely import affinity
from shapely.geometry import LineString, Polygon, box
from shapely.geometry.base import BaseGeometry
from shapely.ops import unary_union

from cama_pipeline.semantics import Semantic
from models.vma.vectors import Vector

_SHIFT = 2  # cv2 fixed-point bits
_COLOURS = {"white": (0.85, 0.85, 0.82), "yellow": (0.85, 0.7, 0.2)}


def procedural_patch(
    size_px: int, resolution_m: float, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray, list[Vector]]:
    """(semantic (S, S) uint8, photometric (S, S, 3) uint8 RGB, vectors in patch pixels (col, row))."""
    px = 1.0 / resolution_m
    roads = [_road(size_px, px, rng)]
    if rng.random() < 0.6:
        roads.append(_road(size_px, px, rng, cross=roads[0][0]))
    surface = unary_union([polygon for _, polygon, _ in roads])
    frame = box(0, 0, size_px, size_px)
    semantic = np.zeros((size_px, size_px), np.uint8)
    photometric = _background(size_px, rng)
    _fill(semantic, photometric, surface, int(Semantic.ROAD), _grey(rng))
    vectors: list[Vector] = []
    curb_px = max(1.0, 0.2 * px)
    for edge in _lines(surface.boundary.intersection(frame)):
        _stroke(semantic, photometric, edge, curb_px, int(Semantic.CURB), (0.6, 0.6, 0.58))
        vectors.append(Vector("boundary", np.asarray(edge.coords)))
    others = [unary_union([p for j, (_, p, _) in enumerate(roads) if j != k]) for k in range(len(roads))]
    for (centre, _polygon, lanes), other in zip(roads, others, strict=True):
        vectors += _dividers(semantic, photometric, centre, lanes, px, other, rng)
    if len(roads) == 2 or rng.random() < 0.3:
        vectors += _crosswalks(semantic, photometric, roads, px, rng)
    photometric = np.clip(photometric + rng.normal(0, 0.03, photometric.shape), 0, 1)
    return semantic, (photometric * 255 + 0.5).astype(np.uint8), _clip_all(vectors, size_px)


def _road(size: int, px: float, rng: np.random.Generator, cross: LineString | None = None):
    """(centreline, road polygon, (lanes per direction, lane width px)) of a road across the patch."""
    centre_xy = rng.uniform(0.25 * size, 0.75 * size, 2)
    angle = rng.uniform(0, np.pi) if cross is None else _angle(cross) + np.pi / 2 + rng.normal(0, 0.15)
    t = np.linspace(-1.5 * size, 1.5 * size, 61)
    bend = rng.normal(0, 0.0008) if rng.random() < 0.5 else 0.0
    x, y = t, bend * t**2
    line = LineString(np.column_stack([x, y]))
    line = affinity.translate(affinity.rotate(line, angle, origin=(0, 0), use_radians=True), *centre_xy)
    lanes = int(rng.integers(1, 4))
    lane_px = rng.uniform(3.0, 3.75) * px
    return line, line.buffer(lanes * lane_px + 0.2 * px, cap_style="flat"), (lanes, lane_px)


def _angle(line: LineString) -> float:
    (x0, y0), (x1, y1) = line.coords[0], line.coords[-1]
    return float(np.arctan2(y1 - y0, x1 - x0))


def _dividers(semantic, photometric, centre, lanes, px, other, rng) -> list[Vector]:
    """Centre line (yellow, double or dashed) and lane lines (white dashed or solid) outside the other road."""
    count, lane_px = lanes
    vectors: list[Vector] = []
    offsets = [(0.0, "yellow", rng.choice(["double", "dashed", "solid"]))]
    offsets += [
        (s * k * lane_px, "white", rng.choice(["dashed", "solid"])) for k in range(1, count) for s in (-1, 1)
    ]
    for offset, colour, style in offsets:
        for line in _lines(centre.offset_curve(offset)) if offset else [centre]:
            vectors += _divider_pieces(semantic, photometric, line, other, colour, style, px, rng)
    return vectors


def _divider_pieces(semantic, photometric, line, other, colour, style, px, rng) -> list[Vector]:
    """Paint one lane line outside the other road and return its pieces as dividers."""
    out = []
    for piece in _lines(line.difference(other.buffer(1.0 * px)) if not other.is_empty else line):
        if piece.length < 2 * px:
            continue
        paint = [piece]
        if style == "double":
            paint = [c for s in (-1, 1) for c in _lines(piece.offset_curve(s * 0.15 * px))]
        for p in paint:
            for dash in _dashes(p, 3.0 * px, 6.0 * px, rng) if style == "dashed" else [p]:
                _stroke(
                    semantic,
                    photometric,
                    dash,
                    max(1.0, 0.15 * px),
                    int(Semantic.LANE_MARKING),
                    _COLOURS[colour],
                )
        out.append(Vector("divider", np.asarray(piece.coords)))
    return out


def _crosswalks(semantic, photometric, roads, px, rng) -> list[Vector]:
    """A zebra crossing across each road, at a random station (next to the crossing road when there is one)."""
    out = []
    for k, (centre, _polygon, (lanes, lane_px)) in enumerate(roads):
        half = lanes * lane_px
        depth = rng.uniform(3.0, 5.0) * px
        station = centre.length / 2 + rng.uniform(-0.15, 0.15) * centre.length / 3
        if len(roads) == 2:
            crossing = roads[1 - k][1]
            hits = centre.intersection(crossing)
            if hits.is_empty:
                continue
            other_half = roads[1 - k][2][0] * roads[1 - k][2][1]
            offset = other_half + 2.0 * px
            station = (
                centre.project(hits.centroid) + float(rng.choice([-1, 1])) * (offset + depth / 2) - depth / 2
            )
        p0 = np.asarray(centre.interpolate(station).coords[0])
        p1 = np.asarray(centre.interpolate(station + 0.01).coords[0])
        d = (p1 - p0) / (np.linalg.norm(p1 - p0) + 1e-9)
        n = np.array([-d[1], d[0]])
        corners = [p0 - n * half, p0 + n * half, p0 + n * half + d * depth, p0 - n * half + d * depth]
        area = Polygon(corners)
        stripe = 0.5 * px
        for s in np.arange(stripe / 2, 2 * half - stripe, 2 * stripe):
            a = p0 - n * half + n * s
            stripe_poly = Polygon([a, a + n * stripe, a + n * stripe + d * depth, a + d * depth])
            _fill(semantic, photometric, stripe_poly, int(Semantic.CROSSWALK), _COLOURS["white"])
        out.append(Vector("ped_crossing", np.asarray(area.exterior.coords)))
    return out


def _dashes(line: LineString, dash: float, gap: float, rng: np.random.Generator) -> list[LineString]:
    out = []
    s = rng.uniform(0, dash + gap)
    while s < line.length:
        seg = [line.interpolate(v) for v in np.linspace(s, min(s + dash, line.length), 4)]
        out.append(LineString(seg))
        s += dash + gap
    return out


def _lines(geometry: BaseGeometry) -> list[LineString]:
    if geometry.is_empty:
        return []
    if isinstance(geometry, LineString):
        return [geometry]
    return [g for g in getattr(geometry, "geoms", []) if isinstance(g, LineString)]


def _fill(semantic, photometric, polygon: BaseGeometry, label: int, colour) -> None:
    polys = [polygon] if isinstance(polygon, Polygon) else list(getattr(polygon, "geoms", []))
    for poly in polys:
        rings = [poly.exterior, *poly.interiors]
        pts = [np.rint((np.asarray(r.coords) - 0.5) * (1 << _SHIFT)).astype(np.int32) for r in rings]
        mask = np.zeros(semantic.shape, np.uint8)
        cv2.fillPoly(mask, pts, 1, shift=_SHIFT)
        semantic[mask > 0] = label
        photometric[mask > 0] = colour


def _stroke(semantic, photometric, line: LineString, width_px: float, label: int, colour) -> None:
    pts = np.rint((np.asarray(line.coords) - 0.5) * (1 << _SHIFT)).astype(np.int32)
    mask = np.zeros(semantic.shape, np.uint8)
    cv2.polylines(mask, [pts], False, 1, thickness=max(1, round(width_px)), shift=_SHIFT)
    semantic[mask > 0] = label
    photometric[mask > 0] = colour


def _background(size: int, rng: np.random.Generator) -> np.ndarray:
    base = rng.uniform([0.2, 0.3, 0.15], [0.45, 0.5, 0.35])
    return np.broadcast_to(base, (size, size, 3)).astype(np.float64).copy()


def _grey(rng: np.random.Generator) -> tuple[float, float, float]:
    g = float(rng.uniform(0.2, 0.4))
    return (g, g, g * 1.02)


def _clip_all(vectors: list[Vector], size: int) -> list[Vector]:
    from models.vma.vectors import clip_vectors

    return clip_vectors(vectors, (0.0, float(size), 0.0, float(size)), min_length_m=4.0)
