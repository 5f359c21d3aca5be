"""Image geometry of the `cama` SRE protocol: CAMA's pixel polyline, skeleton spline normals, normal crossings.

Coordinates are [u = column, v = row] pixels with pixel centres at integers. The distance of a pair is
measured from the image side: along normals of a smoothing spline fitted to the instance skeleton, to where
each normal crosses the projected polyline. A normal that misses the projection (the painted line runs on
past where the projection ends) or crosses it more than once contributes nothing, as in CAMA's code.
"""

import logging
import warnings

import numpy as np
from scipy.interpolate import splev, splprep

from cama_pipeline.evaluate.sre_cama_config import CamaProtocolConfig

logger = logging.getLogger(__name__)

_SAME = 1e-9
"""Two crossings closer than this (in normal-length units) are one point; a smaller |cross product| is parallel."""


def pixel_polyline(points_uv: np.ndarray, width_px: int, height_px: int) -> np.ndarray:
    """CAMA's projected polyline: the distinct integer pixels (floored) inside the image that the projected
    points fall in, ordered by row then column, as [u, v]; (0, 2) when none."""
    points = np.asarray(points_uv, dtype=np.float64)
    inside = (
        (points[:, 0] >= 0) & (points[:, 0] < width_px) & (points[:, 1] >= 0) & (points[:, 1] < height_px)
    )
    pixels = np.floor(points[inside]).astype(np.int64)
    keys = np.unique(pixels[:, 1] * width_px + pixels[:, 0])  # sorted by row, then column
    return np.column_stack([keys % width_px, keys // width_px]).astype(np.float64)


def spline_normals(
    skeleton_uv: np.ndarray, config: CamaProtocolConfig
) -> tuple[np.ndarray, np.ndarray] | None:
    """Centres (N, 2) and unit normals (N, 2) of a smoothing spline through the skeleton pixels taken in the
    given order (row-major, as numpy lists them), or None when the spline cannot be fitted."""
    points = np.asarray(skeleton_uv, dtype=np.float64)
    if len(points) < config.min_points:
        return None
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # FITPACK's "maximal number of iterations" notes
            tck, _ = splprep([points[:, 0], points[:, 1]], s=config.spline_smoothing * len(points))
    except (ValueError, TypeError) as err:
        logger.debug("no spline through %d skeleton pixels: %s", len(points), err)
        return None
    stations = np.linspace(config.spline_range[0], config.spline_range[1], config.normals)
    centres = np.column_stack(splev(stations, tck))
    tangents = np.column_stack(splev(stations, tck, der=1))
    lengths = np.linalg.norm(tangents, axis=1)
    good = lengths > 0
    if not good.any():
        return None
    normals = np.column_stack([-tangents[good, 1], tangents[good, 0]]) / lengths[good, None]
    return centres[good], normals


def normal_distances(
    centres: np.ndarray, normals: np.ndarray, search_px: float, polyline: np.ndarray
) -> np.ndarray:
    """Distance from each normal's centre to where it crosses `polyline` ((M, 2), M >= 2), for the normals
    (segments centre +- search_px * normal) that cross it at exactly one point; the others are left out."""
    starts, directions = _segments(polyline)
    if not len(starts):
        return np.zeros(0)
    origins = centres - search_px * normals
    spans = 2.0 * search_px * normals
    starts, directions = _near_segments(starts, directions, origins, spans)
    if not len(starts):
        return np.zeros(0)
    offset = starts[None, :, :] - origins[:, None, :]
    denominator = _cross(spans[:, None, :], directions[None, :, :])
    scale = np.linalg.norm(spans, axis=1)[:, None] * np.linalg.norm(directions, axis=1)[None, :]
    parallel = np.abs(denominator) <= _SAME * scale
    safe = np.where(parallel, 1.0, denominator)
    along_normal = _cross(offset, directions[None, :, :]) / safe
    along_segment = _cross(offset, spans[:, None, :]) / safe
    hit = ~parallel & _within(along_normal) & _within(along_segment)
    overlap = parallel & _collinear_overlap(offset, spans, directions)
    first = np.where(hit, along_normal, np.inf).min(axis=1)
    last = np.where(hit, along_normal, -np.inf).max(axis=1)
    single = hit.any(axis=1) & (last - first <= _SAME) & ~overlap.any(axis=1)
    return np.abs(first[single] - 0.5) * 2.0 * search_px


def _segments(polyline: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Start points and direction vectors of a polyline's non-degenerate segments."""
    points = np.asarray(polyline, dtype=np.float64)
    directions = np.diff(points, axis=0)
    keep = np.abs(directions).sum(axis=1) > 0
    return points[:-1][keep], directions[keep]


def _near_segments(
    starts: np.ndarray, directions: np.ndarray, origins: np.ndarray, spans: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The segments whose bounding box meets the bounding box of all the normals (the rest cannot cross)."""
    ends = origins + spans
    low = np.minimum(origins, ends).min(axis=0) - 1e-6
    high = np.maximum(origins, ends).max(axis=0) + 1e-6
    seg_low = np.minimum(starts, starts + directions)
    seg_high = np.maximum(starts, starts + directions)
    keep = np.all((seg_high >= low) & (seg_low <= high), axis=1)
    return starts[keep], directions[keep]


def _collinear_overlap(offset: np.ndarray, spans: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """(N, M): the segment lies on the normal's line and shares more than a point with it (CAMA's code then
    gets a line, not a point, and ignores the normal)."""
    span_length = np.linalg.norm(spans, axis=1)[:, None]
    on_line = np.abs(_cross(offset, spans[:, None, :])) <= _SAME * span_length * (1.0 + span_length)
    length2 = np.maximum(span_length**2, 1e-300)
    a = (offset * spans[:, None, :]).sum(axis=2) / length2
    b = ((offset + directions[None]) * spans[:, None, :]).sum(axis=2) / length2
    low = np.maximum(np.minimum(a, b), 0.0)
    high = np.minimum(np.maximum(a, b), 1.0)
    return on_line & (high - low > _SAME)


def _within(values: np.ndarray) -> np.ndarray:
    """Parameters in [0, 1] up to rounding."""
    return (values >= -_SAME) & (values <= 1.0 + _SAME)


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """z component of the 2D cross product of broadcastable (..., 2) arrays."""
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
