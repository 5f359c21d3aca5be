"""Pure geometry of the 3D view: a local frame near the site (viser draws in float32), camera frustum
wireframes, polyline segments, and picking the element nearest to a click ray."""

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class LocalFrame:
    """view = global - origin: keeps coordinates small so float32 rendering does not jitter."""

    origin: np.ndarray
    """(3,) global metres of the view's origin."""

    def from_global(self, points: np.ndarray) -> np.ndarray:
        """(..., 3) global points in the view frame."""
        return np.asarray(points, dtype=np.float64) - self.origin


def frustum_segments(
    view_from_cam: np.ndarray, intrinsic: np.ndarray, width: int, height: int, depth_m: float
) -> np.ndarray:
    """(8, 2, 3) segments of one camera's frustum: four edges from the centre and the far rectangle."""
    corners_px = np.array([[0, 0], [width, 0], [width, height], [0, height]], dtype=np.float64)
    rays = np.column_stack([corners_px, np.ones(4)]) @ np.linalg.inv(intrinsic).T
    corners_cam = rays * depth_m
    corners = corners_cam @ view_from_cam[:3, :3].T + view_from_cam[:3, 3]
    centre = view_from_cam[:3, 3]
    edges = [(centre, corner) for corner in corners]
    rim = [(corners[i], corners[(i + 1) % 4]) for i in range(4)]
    return np.array(edges + rim, dtype=np.float64)


def polyline_segments(points: np.ndarray, *, closed: bool = False) -> np.ndarray:
    """(M, 2, 3) consecutive segments of a 3D polyline (and the closing one for a polygon)."""
    points = np.asarray(points, dtype=np.float64)
    if closed and len(points) > 2 and not np.allclose(points[0], points[-1]):
        points = np.vstack([points, points[:1]])
    return np.stack([points[:-1], points[1:]], axis=1)


def _ray_segment_distance(origin: np.ndarray, direction: np.ndarray, segments: np.ndarray) -> np.ndarray:
    """Distance from a ray to each of (M, 2, 3) segments, sampled densely along the segments."""
    t = np.linspace(0.0, 1.0, 9)
    samples = segments[:, :1, :] + t[None, :, None] * (segments[:, 1:, :] - segments[:, :1, :])
    offsets = samples - origin
    along = np.clip(offsets @ direction, 0.0, None)
    closest = origin + along[..., None] * direction
    return np.asarray(np.linalg.norm(samples - closest, axis=-1).min(axis=1))


def pick_element(
    polylines: Mapping[str, np.ndarray],
    ray_origin: np.ndarray,
    ray_direction: np.ndarray,
    *,
    max_distance_m: float,
) -> str | None:
    """Id of the polyline passing closest to the click ray, if within `max_distance_m` of it; else None."""
    direction = np.asarray(ray_direction, dtype=np.float64)
    norm = float(np.linalg.norm(direction))
    if norm == 0.0:
        return None
    direction = direction / norm
    origin = np.asarray(ray_origin, dtype=np.float64)
    best_id, best = None, max_distance_m
    for element_id, points in polylines.items():
        segments = polyline_segments(points)
        if len(segments) == 0:
            continue
        distance = float(_ray_segment_distance(origin, direction, segments).min())
        if distance <= best:
            best_id, best = element_id, distance
    return best_id
