"""Ground-truth co-visibility of camera pairs: how much of one camera's ground footprint the other sees.

Used to score pair selection (HSP recall). With true poses, the ground camera A sees within a range (sampled on
the ego ground plane, then lifted to the ground-truth elevation raster) is projected into camera B; the share
of those ground points that camera B sees (in front, inside its image, within the same range) is A's
co-visibility with B. Occlusion by buildings or vehicles is not modelled.

Only cameras whose centres are within `2 * max_range_m` (plus a margin) of each other in x, y are compared: A's
ground points lie within the range of A and B sees only points within the range of B, so cameras further apart
share nothing and their entry is exactly 0. This makes the matrix linear rather than quadratic in work on a long
site (the large synthetic site's 5,000 images), with the same values.
"""

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree
from tqdm import tqdm

from cama_pipeline.cameras import CameraView
from cama_pipeline.pairs.footprint import ground_hits_ego

NEIGHBOUR_MARGIN_M = 2.0
"""Slack on the `2 * max_range_m` neighbour radius: ground points are sampled on the tilted ego plane around the
camera's foot, so their horizontal distance from the camera centre can exceed the range by height * tilt."""


@dataclass(frozen=True, eq=False)
class ElevationSurface:
    """A ground-truth elevation raster (DESIGN.md convention) sampled at global x, y (NaN where unknown)."""

    elevation: np.ndarray
    origin_xy: tuple[float, float]
    resolution: float

    def height(self, xy: np.ndarray) -> np.ndarray:
        """(N,) elevation at (N, 2) global points, nearest cell; NaN outside the raster or unobserved."""
        cols = np.round((xy[:, 0] - self.origin_xy[0]) / self.resolution).astype(int)
        rows = np.round((self.origin_xy[1] - xy[:, 1]) / self.resolution).astype(int)
        inside = (
            (rows >= 0) & (rows < self.elevation.shape[0]) & (cols >= 0) & (cols < self.elevation.shape[1])
        )
        out = np.full(len(xy), np.nan)
        out[inside] = self.elevation[rows[inside], cols[inside]]
        return out


@dataclass(frozen=True, eq=False)
class CameraStack:
    """The projection of many cameras as stacked arrays, computed once and indexed per query."""

    cam_from_world: np.ndarray
    """(N, 4, 4)."""
    intrinsic: np.ndarray
    """(N, 3, 3)."""
    size: np.ndarray
    """(N, 2) width, height in pixels."""

    @classmethod
    def of(cls, views: list[CameraView]) -> "CameraStack":
        """Stack the cameras of `views`."""
        return cls(
            np.linalg.inv(np.stack([v.world_from_cam for v in views])),
            np.stack([v.intrinsic for v in views]),
            np.array([(v.width, v.height) for v in views], dtype=float),
        )


def ground_points(
    view: CameraView, surface: ElevationSurface, grid: tuple[int, int], max_range_m: float
) -> np.ndarray:
    """(M, 3) global points of the view's ground footprint, on the true surface where it is known."""
    hits = ground_hits_ego(view, grid, max_range_m)
    world = (view.world_from_ego[:3, :3] @ np.c_[hits, np.zeros(len(hits))].T).T + view.world_from_ego[:3, 3]
    world[:, 2] = surface.height(world[:, :2])
    return world[np.isfinite(world[:, 2])]


def seen_share(
    points: np.ndarray, cameras: CameraStack, max_range_m: float, which: np.ndarray | None = None
) -> np.ndarray:
    """Share of `points` each camera (of `which`, all when None) sees: in front, inside the image, within range."""
    index = np.arange(len(cameras.size)) if which is None else which
    if len(points) == 0 or len(index) == 0:
        return np.zeros(len(index))
    cam_from_world = cameras.cam_from_world[index]
    local = cam_from_world[:, :3, :3] @ points.T + cam_from_world[:, :3, 3:4]
    z = local[:, 2]
    safe_z = np.where(z > 1e-6, z, 1.0)
    uv = cameras.intrinsic[index, :2] @ (local / safe_z[:, None])
    size = cameras.size[index]
    inside = (uv[:, 0] >= 0) & (uv[:, 0] < size[:, :1]) & (uv[:, 1] >= 0) & (uv[:, 1] < size[:, 1:])
    near = np.einsum("nkm,nkm->nm", local, local) <= max_range_m**2
    return np.asarray(((z > 1e-6) & inside & near).mean(axis=1))


def neighbours(views: list[CameraView], max_range_m: float) -> list[np.ndarray]:
    """For each view, the indices of the views that can share ground with it (centres within
    `2 * max_range_m + NEIGHBOUR_MARGIN_M` in x, y), itself included."""
    if not views:
        return []
    centres = np.stack([v.center[:2] for v in views])
    found = cKDTree(centres).query_ball_point(centres, 2 * max_range_m + NEIGHBOUR_MARGIN_M)
    return [np.asarray(sorted(near), dtype=int) for near in found]


def covisibility_matrix(
    views: list[CameraView],
    surface: ElevationSurface,
    *,
    grid: tuple[int, int] = (25, 90),
    max_range_m: float = 25.0,
    show_progress: bool = False,
) -> np.ndarray:
    """(N, N) float32 matrix C with C[a, b] = share of a's true ground footprint seen by b (diagonal 1)."""
    matrix = np.zeros((len(views), len(views)), dtype=np.float32)
    if not views:
        return matrix
    cameras = CameraStack.of(views)
    near = neighbours(views, max_range_m)
    for a, view in enumerate(tqdm(views, desc="co-visibility", disable=not show_progress)):
        points = ground_points(view, surface, grid, max_range_m)
        matrix[a, near[a]] = seen_share(points, cameras, max_range_m, near[a])
        matrix[a, a] = 1.0
    return matrix
