"""The elevation MLP: z(x, y) with a low-frequency positional encoding, fitted robustly to surface points.

Road elevation changes slowly, so a few encoding octaves keep the surface smooth by design: one bad point
cannot raise a spike. The MLP is evaluated on a coarse control grid and interpolated to the mesh vertices,
which is exact enough for so smooth a function and keeps every optimisation step cheap.
"""

import math
from collections.abc import Callable
from typing import TypeVar

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from cama_pipeline.surface.config import SurfaceConfig
from cama_pipeline.surface.grid import SurfaceGrid

BATCH_POINTS = 4096
SMOOTHNESS_SAMPLES = 256
"""Road-region places per step where the curvature prior is evaluated."""
Index = TypeVar("Index", np.ndarray, torch.Tensor)
"""Cell columns or rows, as numpy (built once) or torch (built per call on the heights' device)."""
_STENCIL = torch.tensor(
    [[0, 0], [1, 0], [-1, 0], [0, 1], [0, -1], [1, 1], [1, -1], [-1, 1], [-1, -1]], dtype=torch.float64
)


class ElevationMLP(nn.Module):
    """z = offset + MLP(positional encoding of the normalised x, y); global metres in and out."""

    centre: torch.Tensor
    octaves: torch.Tensor

    def __init__(self, frequencies: int, width: int, centre_xy: np.ndarray, scale_m: float, offset_m: float):
        super().__init__()
        self.register_buffer("centre", torch.as_tensor(centre_xy, dtype=torch.float64))
        self.scale_m = float(scale_m)
        self.offset_m = float(offset_m)
        self.register_buffer("octaves", math.pi * 2.0 ** torch.arange(frequencies, dtype=torch.float32))
        inputs = 2 + 4 * frequencies
        self.net = nn.Sequential(
            nn.Linear(inputs, width), nn.SiLU(), nn.Linear(width, width), nn.SiLU(), nn.Linear(width, 1)
        )

    def encode(self, xy: torch.Tensor) -> torch.Tensor:
        """(N, 2 + 4F): the normalised coordinates and their sines and cosines."""
        u = ((xy.double() - self.centre) / self.scale_m).float()
        angles = (u[:, :, None] * self.octaves).reshape(len(u), -1)
        return torch.cat([u, torch.sin(angles), torch.cos(angles)], dim=1)

    def forward(self, xy: torch.Tensor) -> torch.Tensor:
        return self.net(self.encode(xy))[:, 0] + self.offset_m


def huber(residual: torch.Tensor, scale: float) -> torch.Tensor:
    """Mean Huber loss (quadratic within `scale`, linear beyond), in metres."""
    return F.huber_loss(residual, torch.zeros_like(residual), delta=scale)


def curvature_energy(mlp: ElevationMLP, xy: torch.Tensor, step_m: float) -> torch.Tensor:
    """Mean thin-plate energy z_xx^2 + 2 z_xy^2 + z_yy^2 (m^-2) of the MLP at (N, 2) places, by central
    differences of `step_m`: zero for a plane, so it makes the surface extrapolate like one."""
    z = mlp((xy[:, None, :] + _STENCIL.to(xy.device) * step_m).reshape(-1, 2)).reshape(len(xy), -1)
    z_xx = (z[:, 1] + z[:, 2] - 2 * z[:, 0]) / step_m**2
    z_yy = (z[:, 3] + z[:, 4] - 2 * z[:, 0]) / step_m**2
    z_xy = (z[:, 5] - z[:, 6] - z[:, 7] + z[:, 8]) / (4 * step_m**2)
    return (z_xx**2 + 2 * z_xy**2 + z_yy**2).mean()


def surface_loss(
    mlp: ElevationMLP,
    points: torch.Tensor,
    region_xy: torch.Tensor | None,
    config: SurfaceConfig,
    generator: torch.Generator,
) -> torch.Tensor:
    """Huber loss on a random batch of the points plus the weighted curvature prior on a random batch
    of the road region (none when `region_xy` is None or the weight is 0)."""
    batch = points
    if len(points) > BATCH_POINTS:
        batch = points[torch.randint(len(points), (BATCH_POINTS,), generator=generator).to(points.device)]
    loss = huber(mlp(batch[:, :2]) - batch[:, 2].float(), config.huber_m)
    if region_xy is not None and len(region_xy) and config.smoothness_weight > 0:
        pick = torch.randint(len(region_xy), (SMOOTHNESS_SAMPLES,), generator=generator)
        energy = curvature_energy(mlp, region_xy[pick.to(region_xy.device)], config.smoothness_step_m)
        loss = loss + config.smoothness_weight * energy
    return loss


def new_elevation_mlp(grid: SurfaceGrid, points_z: np.ndarray, config: SurfaceConfig) -> ElevationMLP:
    """An MLP normalised to the grid's extent, its offset the points' median height."""
    extent = np.array([(grid.cols - 1), (grid.rows - 1)]) * grid.resolution_m
    centre = np.array([grid.origin_xy[0] + extent[0] / 2, grid.origin_xy[1] - extent[1] / 2])
    return ElevationMLP(
        config.pe_frequencies,
        config.mlp_width,
        centre,
        max(extent.max() / 2, 1.0),
        float(np.median(points_z)),
    )


def fit_elevation(
    mlp: ElevationMLP,
    points: torch.Tensor,
    config: SurfaceConfig,
    on_step: Callable[[int, float], None] | None = None,
    region_xy: torch.Tensor | None = None,
    steps: int | None = None,
) -> list[float]:
    """Fit `mlp` to (N, 3) points with Adam and `surface_loss` (the curvature prior over the (V, 2) road
    region `region_xy` when given) for `steps` (default `elevation_iterations`); the loss every 50 steps and at
    the last, each also passed to `on_step` with the number of steps taken since its previous call."""
    optimiser = torch.optim.Adam(mlp.parameters(), lr=config.elevation_lr)
    steps = config.elevation_iterations if steps is None else steps
    schedule = torch.optim.lr_scheduler.CosineAnnealingLR(
        optimiser, max(steps, 1), eta_min=config.elevation_lr / 20
    )
    generator = torch.Generator().manual_seed(config.seed)
    losses: list[float] = []
    reported = 0
    for step in range(steps):
        optimiser.zero_grad()
        loss = surface_loss(mlp, points, region_xy, config, generator)
        loss.backward()
        optimiser.step()
        schedule.step()
        if step % 50 == 0 or step == steps - 1:
            losses.append(loss.item())
            if on_step is not None:
                on_step(step + 1 - reported, losses[-1])
            reported = step + 1
    return losses


class ControlGrid:
    """The MLP's coarse evaluation grid over a SurfaceGrid, and the vertices' places in it."""

    def __init__(self, grid: SurfaceGrid, spacing_m: float, device: torch.device):
        step = max(1, int(round(spacing_m / grid.resolution_m)))
        self.spacing_m = step * grid.resolution_m
        self.rows = (grid.rows - 1) // step + 2
        self.cols = (grid.cols - 1) // step + 2
        r, c = np.meshgrid(np.arange(self.rows) * step, np.arange(self.cols) * step, indexing="ij")
        self.xy = torch.as_tensor(grid.xy_of_cells(r.ravel(), c.ravel()), device=device)
        self._step = step
        self._cells = (grid.rows, grid.cols)
        vr, vc = grid.vertex_cells()
        gx, gy = self._sample_coordinates(vc, vr)
        self.vertex_grid = torch.as_tensor(np.stack([gx, gy], axis=1), dtype=torch.float32, device=device)

    def _sample_coordinates(self, col: Index, row: Index) -> tuple[Index, Index]:
        """`grid_sample` coordinates (x, y in [-1, 1] over the control grid) of cells at grid columns and rows
        (numpy or torch)."""
        return (
            col / (self._step * (self.cols - 1)) * 2 - 1,
            row / (self._step * (self.rows - 1)) * 2 - 1,
        )

    def heights(self, mlp: ElevationMLP) -> torch.Tensor:
        """(rows, cols) MLP heights at the control points."""
        return mlp(self.xy).reshape(self.rows, self.cols)

    def at_vertices(self, control_z: torch.Tensor, vertex_ids: torch.Tensor | None = None) -> torch.Tensor:
        """Heights of the given vertices (all when None), bilinear in the control grid."""
        where = self.vertex_grid if vertex_ids is None else self.vertex_grid[vertex_ids]
        sampled = F.grid_sample(control_z[None, None], where[None, None], mode="bilinear", align_corners=True)
        return sampled[0, 0, 0]

    def at_cells(self, control_z: torch.Tensor) -> torch.Tensor:
        """(rows, cols) heights of every cell of the grid (the road region's and the others), bilinear in the
        control grid as `at_vertices`."""
        rows, cols = self._cells
        gx, gy = self._sample_coordinates(
            torch.arange(cols, dtype=torch.float64, device=control_z.device),
            torch.arange(rows, dtype=torch.float64, device=control_z.device),
        )
        where = torch.stack(torch.meshgrid(gx, gy, indexing="xy"), dim=-1).float()
        sampled = F.grid_sample(control_z[None, None], where[None], mode="bilinear", align_corners=True)
        return sampled[0, 0]

    def normals(self, control_z: torch.Tensor) -> torch.Tensor:
        """(V, 3) unit upward surface normals at the vertices (world frame; rows grow with -y)."""
        d_row, d_col = torch.gradient(control_z.detach(), spacing=self.spacing_m)
        slopes = torch.stack([-d_col, d_row])
        sampled = F.grid_sample(slopes[None], self.vertex_grid[None, None], align_corners=True)[0, :, 0]
        normals = torch.cat([sampled, torch.ones_like(sampled[:1])]).T
        return normals / normals.norm(dim=1, keepdim=True)
