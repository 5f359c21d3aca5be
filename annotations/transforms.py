"""Vectorised point transforms between site, global, ego and BEV-pixel coordinates (pure numpy).

Frames (DESIGN.md): global metres; site = global - site_origin_xy (x and y only, z unchanged); ego x forward,
y left, z up, placed by `global_from_ego` (rotation matrix R, translation t: p_global = R p_ego + t); BEV pixels
(col, row) with pixel centres at integers, pixel (0, 0)'s centre at the raster's `origin_xy` (global metres),
columns growing with +x and rows with -y. Every function takes (N, 2) or (N, 3) points (ego transforms: (N, 3)).
"""

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from annotations.schema import Georeference


def _points(points: ArrayLike, *, field: str = "points", dims: Sequence[int] = (2, 3)) -> np.ndarray:
    """`points` as a float (N, D) array with D in `dims`; ValueError naming `field` otherwise."""
    array = np.asarray(points, dtype=float)
    if array.ndim != 2 or array.shape[1] not in dims:
        wanted = " or ".join(f"(N, {d})" for d in dims)
        raise ValueError(f"{field}: expected an array of shape {wanted}, got {array.shape}")
    return array


def _shift_xy(points: ArrayLike, offset_xy: ArrayLike, sign: float) -> np.ndarray:
    """Add `sign * offset_xy` to x and y, leaving any z alone."""
    out = _points(points).copy()
    offset = np.asarray(offset_xy, dtype=float)
    if offset.shape != (2,):
        raise ValueError(f"site_origin_xy: expected [x, y], got shape {offset.shape}")
    out[:, :2] += sign * offset
    return out


def global_from_site_points(points: ArrayLike, site_origin_xy: ArrayLike) -> np.ndarray:
    """Site coordinates to global metres: add the site origin to x and y."""
    return _shift_xy(points, site_origin_xy, 1.0)


def site_from_global_points(points: ArrayLike, site_origin_xy: ArrayLike) -> np.ndarray:
    """Global metres to site coordinates: subtract the site origin from x and y."""
    return _shift_xy(points, site_origin_xy, -1.0)


def _pose(rotation: ArrayLike, translation: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Validate a (3, 3) rotation and (3,) translation and return them as float arrays."""
    r = np.asarray(rotation, dtype=float)
    t = np.asarray(translation, dtype=float)
    if r.shape != (3, 3):
        raise ValueError(f"rotation: expected a (3, 3) matrix, got shape {r.shape}")
    if t.shape != (3,):
        raise ValueError(f"translation: expected [x, y, z], got shape {t.shape}")
    if not (np.isfinite(r).all() and np.isfinite(t).all()):
        raise ValueError("rotation/translation: must be finite")
    if not np.allclose(r @ r.T, np.eye(3), atol=1e-6) or np.linalg.det(r) <= 0:
        raise ValueError("rotation: not a proper rotation matrix (R R^T != I or det(R) <= 0)")
    return r, t


def global_from_ego_points(
    points: ArrayLike, global_from_ego_rotation: ArrayLike, global_from_ego_translation: ArrayLike
) -> np.ndarray:
    """Ego-frame points to global metres: p_global = R p_ego + t."""
    r, t = _pose(global_from_ego_rotation, global_from_ego_translation)
    return _points(points, dims=(3,)) @ r.T + t


def ego_from_global_points(
    points: ArrayLike, global_from_ego_rotation: ArrayLike, global_from_ego_translation: ArrayLike
) -> np.ndarray:
    """Global points into the ego frame of the pose `global_from_ego`: p_ego = R^T (p_global - t)."""
    r, t = _pose(global_from_ego_rotation, global_from_ego_translation)
    return (_points(points, dims=(3,)) - t) @ r


def rotation_from_quaternion(quaternion_wxyz: ArrayLike) -> np.ndarray:
    """The (3, 3) rotation matrix of a quaternion stored w, x, y, z (normalised here)."""
    q = np.asarray(quaternion_wxyz, dtype=float)
    norm = float(np.linalg.norm(q)) if q.shape == (4,) else 0.0
    if not np.isfinite(norm) or norm == 0.0:
        raise ValueError(f"quaternion_wxyz: expected 4 finite numbers, not all zero, got {q.tolist()}")
    w, x, y, z = q / norm
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def pixel_from_global_points(points: ArrayLike, georef: Georeference) -> np.ndarray:
    """Global x, y (z ignored) to BEV pixel (col, row), fractional; pixel centres are at integers."""
    return georef.pixel_from_global(_points(points))


def global_from_pixel_points(pixels: ArrayLike, georef: Georeference) -> np.ndarray:
    """BEV pixel (col, row) to global x, y in metres."""
    return georef.global_from_pixel(_points(pixels, field="pixels", dims=(2,)))


def pixel_from_site_points(points: ArrayLike, georef: Georeference) -> np.ndarray:
    """Site x, y (z ignored) to BEV pixel (col, row) through the georeference's site origin."""
    return pixel_from_global_points(global_from_site_points(points, georef.site_origin_xy), georef)


def site_from_pixel_points(pixels: ArrayLike, georef: Georeference) -> np.ndarray:
    """BEV pixel (col, row) to site x, y in metres."""
    return site_from_global_points(global_from_pixel_points(pixels, georef), georef.site_origin_xy)
