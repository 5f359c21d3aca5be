"""The site's road region and elevation from its surface points, the trajectory strip trusted first.

The strip lies under the cameras and is road by construction; SfM road points are sparse and, beyond a
few metres from the cameras, often triangulated decimetres to metres off. So the strip alone sets the
road region and is fitted first; then the SfM points inside the region and within `sfm_gate_m` of that
surface join it for a second, shorter fit warm-started from the first. With `sfm_gate_rounds` > 1 the points
are gated again against each new fit and fitted again while the inliers grow: beyond the strip the first fit
continues like a plane (the curvature prior), so where the road's grade changes past the trajectory's end the
points there lie further than the gate from it, and only a surface pulled towards the points nearer in brings
them within it. Without a strip, every point is trusted.
"""

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import torch

from cama_pipeline.surface.config import SurfaceConfig
from cama_pipeline.surface.elevation import ElevationMLP, fit_elevation, new_elevation_mlp
from cama_pipeline.surface.grid import SurfaceGrid, road_grid
from cama_pipeline.surface.points import SurfacePoints


@dataclass(frozen=True, eq=False)
class FittedSurface:
    """The road region, its fitted elevation MLP and the points it was fitted to."""

    grid: SurfaceGrid
    mlp: ElevationMLP
    points: torch.Tensor
    """(N, 3) the strip and the SfM points kept."""
    sfm_kept: int
    losses: list[float]
    """The Huber + prior loss every 50 steps of both fits."""


def fit_steps(points: SurfacePoints, config: SurfaceConfig) -> int:
    """Adam steps `fit_surface` takes (for progress): two fits when SfM points may join the strip."""
    refit = config.refit_iterations * config.sfm_gate_rounds if points.strip_count and points.sfm_count else 0
    return config.elevation_iterations + refit


def gate(mlp: ElevationMLP, xyz: np.ndarray, gate_m: float) -> np.ndarray:
    """(N,) whether each point lies within `gate_m` of the MLP's surface."""
    with torch.no_grad():
        z = mlp(torch.as_tensor(xyz[:, :2], device=mlp.centre.device)).double().cpu().numpy()
    return np.asarray(np.abs(z - xyz[:, 2]) <= gate_m)


def fit_surface(
    points: SurfacePoints,
    config: SurfaceConfig,
    device: torch.device,
    on_step: Callable[[int, float], None] | None = None,
) -> FittedSurface:
    """Region and elevation (see the module docstring)."""
    strip, sfm = points.xyz[: points.strip_count], points.xyz[points.strip_count :]
    trusted = strip if len(strip) else points.xyz
    grid = road_grid(trusted[:, :2], config.resolution_m, config.region_radius_m)
    mlp = new_elevation_mlp(grid, trusted[:, 2], config).to(device)
    region = torch.as_tensor(grid.vertex_xy(), device=device)
    trusted_points = torch.as_tensor(trusted, device=device)
    fitted = trusted_points
    losses = fit_elevation(mlp, fitted, config, on_step, region)
    kept = np.zeros(len(sfm), dtype=bool)
    if len(strip) and len(sfm):
        in_region = grid.in_region(sfm[:, :2])
        for fit_round in range(config.sfm_gate_rounds):
            inliers = in_region & gate(mlp, sfm, config.sfm_gate_m)
            if fit_round and not (inliers & ~kept).any():  # none joins: the fit would be the last again
                if on_step is not None:
                    on_step(config.refit_iterations * (config.sfm_gate_rounds - fit_round), losses[-1])
                break
            kept = inliers
            fitted = torch.cat([trusted_points, torch.as_tensor(sfm[kept], device=device)])
            losses += fit_elevation(mlp, fitted, config, on_step, region, config.refit_iterations)
    return FittedSurface(grid, mlp, fitted, int(kept.sum()), losses)
