"""Ground-truth co-visibility of camera pairs: how much of one camera's ground footprint the other sees.

Used to score pair selection (HSP recall). With true poses, the ground camera A sees within a range (sampled on
the ego ground plane, then lifted to the ground-truth elevation raster) is projected into camera B; the share
of those ground points that camera B sees (in front, inside its image, within the same range) is A's
co-visibility with B. Occlusion by buildings or vehicles is not modelled.
"""

from dataclasses import dataclass

import numpy as np

from cama_pipeline.pairs.cameras import CameraView
from cama_pipeline.pairs.footprint import ground_hits_ego


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


def ground_points(
    view: CameraView, surface: ElevationSurface, grid: tuple[int, int], max_range_m: float
) -> np.ndarray:
    """(M, 3) global points of the view's ground footprint, on the true surface where it is known."""
    hits = ground_hits_ego(view, grid, max_range_m)
    world = (view.world_from_ego[:3, :3] @ np.c_[hits, np.zeros(len(hits))].T).T + view.world_from_ego[:3, 3]
    world[:, 2] = surface.height(world[:, :2])
    return world[np.isfinite(world[:, 2])]


def seen_share(points: np.ndarray, views: list[CameraView], max_range_m: float) -> np.ndarray:
    """(len(views),) share of `points` each view sees: in front, inside the image, within range."""
    if len(points) == 0:
        return np.zeros(len(views))
    cam_from_world = np.linalg.inv(np.stack([v.world_from_cam for v in views]))
    local = np.einsum("nij,mj->nmi", cam_from_world[:, :3, :3], points) + cam_from_world[:, None, :3, 3]
    intrinsics = np.stack([v.intrinsic for v in views])
    z = local[..., 2]
    safe_z = np.where(z > 1e-6, z, 1.0)
    uv = np.einsum("nij,nmj->nmi", intrinsics[:, :2, :], local / safe_z[..., None])
    widths = np.array([v.width for v in views])[:, None]
    heights = np.array([v.height for v in views])[:, None]
    inside = (uv[..., 0] >= 0) & (uv[..., 0] < widths) & (uv[..., 1] >= 0) & (uv[..., 1] < heights)
    near = np.linalg.norm(local, axis=2) <= max_range_m
    return np.asarray(((z > 1e-6) & inside & near).mean(axis=1))


def covisibility_matrix(
    views: list[CameraView],
    surface: ElevationSurface,
    *,
    grid: tuple[int, int] = (25, 90),
    max_range_m: float = 25.0,
) -> np.ndarray:
    """(N, N) matrix C with C[a, b] = share of a's true ground footprint seen by b (diagonal 1)."""
    matrix = np.zeros((len(views), len(views)))
    for a, view in enumerate(views):
        matrix[a] = seen_share(ground_points(view, surface, grid, max_range_m), views, max_range_m)
        matrix[a, a] = 1.0
    return matrix
