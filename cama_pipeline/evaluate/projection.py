"""Projection of 3D map polylines (global metres) into a pinhole camera image, cut into visible pieces.

A polyline is densified, cropped to a range around the camera, clipped to the half-space in front of the
camera and then to the image rectangle. Straight 3D segments project to straight image segments, so the
clipping in the image is exact; the range crop interpolates along each segment (within the densify spacing).
Piece ends cut by the range crop are marked `open`: the map was not evaluated beyond them.
"""

import logging
from dataclasses import dataclass

import numpy as np

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class ProjectionConfig:
    """How map polylines are cut and projected."""

    range_m: float = 50.0
    """Keep map points at most this far (3D distance) from the camera centre."""
    near_m: float = 0.5
    """Keep map points at least this far in front of the camera (camera z)."""
    spacing_m: float = 0.5
    """Densify polylines to at most this vertex spacing before cropping."""

    def __post_init__(self) -> None:
        if not self.range_m > 0 or not self.spacing_m > 0:
            raise ValueError(
                f"ProjectionConfig: range_m and spacing_m must be > 0, got {self.range_m}, {self.spacing_m}"
            )
        if not 0 < self.near_m < self.range_m:
            raise ValueError(f"ProjectionConfig.near_m must be in (0, range_m), got {self.near_m}")


@dataclass(frozen=True, eq=False)
class PinholeCamera:
    """A camera's pose and intrinsics, plain arrays (no dependency on the data model)."""

    global_from_cam_rotation: np.ndarray
    """(3, 3) rotation of camera (OpenCV axes) vectors into the global frame."""
    global_from_cam_translation: np.ndarray
    """(3,) camera centre in global metres."""
    intrinsic: np.ndarray
    """(3, 3) pinhole matrix K in pixels."""
    width: int
    """Image width in pixels."""
    height: int
    """Image height in pixels."""

    def __post_init__(self) -> None:
        rotation = np.asarray(self.global_from_cam_rotation, dtype=np.float64)
        translation = np.asarray(self.global_from_cam_translation, dtype=np.float64)
        intrinsic = np.asarray(self.intrinsic, dtype=np.float64)
        if rotation.shape != (3, 3) or translation.shape != (3,) or intrinsic.shape != (3, 3):
            raise ValueError(
                "PinholeCamera: rotation and intrinsic must be 3x3 and translation (3,), got "
                f"{rotation.shape}, {intrinsic.shape}, {translation.shape}"
            )
        if not (
            np.isfinite(rotation).all() and np.isfinite(translation).all() and np.isfinite(intrinsic).all()
        ):
            raise ValueError("PinholeCamera: pose and intrinsic must be finite")
        if self.width <= 0 or self.height <= 0:
            raise ValueError(f"PinholeCamera: image size must be positive, got {self.width}x{self.height}")
        object.__setattr__(self, "global_from_cam_rotation", rotation)
        object.__setattr__(self, "global_from_cam_translation", translation)
        object.__setattr__(self, "intrinsic", intrinsic)

    def cam_from_global(self, points: np.ndarray) -> np.ndarray:
        """Map (N, 3) global points into the camera frame."""
        return (points - self.global_from_cam_translation) @ self.global_from_cam_rotation


@dataclass(frozen=True, eq=False)
class ProjectedPiece:
    """One visible piece of a projected polyline."""

    points_px: np.ndarray
    """(M, 2) pixel coordinates [u = column, v = row], M >= 2, pixel centres at integers."""
    start_open: bool
    """True when the piece starts where the range crop cut the polyline."""
    end_open: bool
    """True when the piece ends where the range crop cut the polyline."""


def densify(points: np.ndarray, spacing_m: float, *, closed: bool = False) -> np.ndarray:
    """Insert vertices so that no segment is longer than `spacing_m` (a closed ring gets its closing edge)."""
    points = _check_polyline(points, "points")
    if spacing_m <= 0:
        raise ValueError(f"spacing_m must be > 0, got {spacing_m}")
    if closed and not np.array_equal(points[0], points[-1]):
        points = np.vstack([points, points[:1]])
    segments = np.diff(points, axis=0)
    counts = np.maximum(1, np.ceil(np.linalg.norm(segments, axis=1) / spacing_m).astype(np.int64))
    index = np.repeat(np.arange(len(segments)), counts)
    step = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
    fraction = step / np.repeat(counts, counts)
    dense = points[index] + fraction[:, None] * segments[index]
    return np.vstack([dense, points[-1:]])


def project_polyline(
    points: np.ndarray, camera: PinholeCamera, config: ProjectionConfig, *, closed: bool = False
) -> list[ProjectedPiece]:
    """Visible image pieces of one 3D polyline (global metres); empty when nothing is in view."""
    points = _check_polyline(points, "points")
    if points.shape[1] != 3:
        raise ValueError(f"points must be (N, 3) global metres, got shape {points.shape}")
    cam = camera.cam_from_global(densify(points, config.spacing_m, closed=closed))
    pieces = _split(cam, config.range_m - np.linalg.norm(cam, axis=1), False, False, cut_open=True)
    pieces = [q for p in pieces for q in _split(p[0], p[0][:, 2] - config.near_m, p[1], p[2], cut_open=False)]
    out: list[ProjectedPiece] = []
    for cam_points, start_open, end_open in pieces:
        uvw = cam_points @ camera.intrinsic.T
        clipped = [(uvw[:, :2] / uvw[:, 2:3], start_open, end_open)]
        for axis, bound, sign in _image_edges(camera.width, camera.height):
            clipped = [
                q
                for p in clipped
                for q in _split(p[0], sign * (p[0][:, axis] - bound), p[1], p[2], cut_open=False)
            ]
        out.extend(ProjectedPiece(uv, s, e) for uv, s, e in clipped if _length(uv) > 1e-9)
    return out


def _image_edges(width: int, height: int) -> list[tuple[int, float, float]]:
    """Half-planes (axis, bound, sign) whose intersection is the image: sign * (coord - bound) >= 0."""
    return [(0, -0.5, 1.0), (0, width - 0.5, -1.0), (1, -0.5, 1.0), (1, height - 0.5, -1.0)]


def _split(
    points: np.ndarray, keep: np.ndarray, start_open: bool, end_open: bool, *, cut_open: bool
) -> list[tuple[np.ndarray, bool, bool]]:
    """Runs of a polyline where `keep` >= 0, ends interpolated where it crosses zero; new ends get `cut_open`."""
    inside = keep >= 0
    if inside.all():
        return [(points, start_open, end_open)]
    kept = np.flatnonzero(inside)
    if kept.size == 0:
        return []
    breaks = np.flatnonzero(np.diff(kept) > 1)
    starts = np.concatenate([kept[:1], kept[breaks + 1]])
    ends = np.concatenate([kept[breaks], kept[-1:]])
    last = len(points) - 1
    runs = []
    for s, e in zip(starts, ends, strict=True):
        parts = [points[s : e + 1]]
        if s > 0:
            parts.insert(0, _crossing(points[s - 1], points[s], keep[s - 1], keep[s]))
        if e < last:
            parts.append(_crossing(points[e], points[e + 1], keep[e], keep[e + 1]))
        run = np.vstack(parts)
        if len(run) >= 2:
            runs.append((run, start_open if s == 0 else cut_open, end_open if e == last else cut_open))
    return runs


def _crossing(a: np.ndarray, b: np.ndarray, fa: float, fb: float) -> np.ndarray:
    """The point on segment a-b where the linearly interpolated value goes from fa to zero to fb."""
    weight = fa / (fa - fb)
    return (a + weight * (b - a))[None, :]


def _length(points: np.ndarray) -> float:
    """Length of a polyline."""
    return float(np.linalg.norm(np.diff(points, axis=0), axis=1).sum())


def _check_polyline(points: np.ndarray, name: str) -> np.ndarray:
    """`points` as a finite float (N, D) array with N >= 2, or ValueError naming it."""
    array = np.asarray(points, dtype=np.float64)
    if array.ndim != 2 or array.shape[0] < 2 or array.shape[1] not in (2, 3):
        raise ValueError(f"{name} must be an (N, 2) or (N, 3) polyline with N >= 2, got shape {array.shape}")
    if not np.isfinite(array).all():
        raise ValueError(f"{name} must be finite (found NaN or inf)")
    return array
