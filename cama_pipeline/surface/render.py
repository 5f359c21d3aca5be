"""Differentiable rendering of the road mesh into the keyframe images: camera rays cast onto the height field.

RoMe renders its mesh into every image and optimises colour, semantics and elevation against the pixels. The
surface here is a height field on the BEV grid (one vertex per cell centre, bilinear between them), so rendering a
pixel is finding where its ray first meets the field, then reading the mesh's attributes there:

1. a first hit on the smooth surface (the elevation MLP on its control grid), by fixed-point iteration;
2. a bracketing search along the ray over heights `search_m` around that hit, on the full field (the smooth
   surface, the kerb steps and the per-vertex residual): the first sample below the field and the one before it
   bracket the hit, which a secant step places; a ray that grazes a kerb stops on its face, as the camera sees it;
3. one Newton step from that (detached) hit on the field, which keeps the hit's value and carries the gradient of
   the ray's length with respect to the field's heights (the implicit-function derivative), so a colour edge seen
   in the wrong place pulls the heights that put it there;
4. the vertices' colour and semantic logits interpolated bilinearly at the hit.

Everything is torch and vectorised over rays. The search reads two detached height rasters of the grid (the smooth
surface, and the full surface on the region's cells); the Newton step and the attributes read the vertices, so the
gradients reach only the vertices around each hit. A ray whose hit has a cell outside the road region among its
four neighbours is dropped, as are rays that leave the camera's range or never come down to the road.
"""

from dataclasses import dataclass

import torch

from cama_pipeline.surface.grid import SurfaceGrid

FIXED_POINT_ITERATIONS = 4
SLOPE_FLOOR = 1e-3
"""Rays descending less steeply than this (m of height per m of ray) are too grazing to place."""


@dataclass(frozen=True, eq=False)
class HeightField:
    """The mesh as its grid, per-vertex heights and attributes, and two detached height rasters of the grid."""

    grid: SurfaceGrid
    vertex_id: torch.Tensor
    """(rows, cols) long: each cell's vertex, -1 outside the road region."""
    height: torch.Tensor
    """(V,) full heights: smooth + kerb step + residual (differentiable in the residual)."""
    attributes: torch.Tensor
    """(V, C) per-vertex attributes (colour, then logits)."""
    smooth: torch.Tensor
    """(rows, cols) float32 the elevation MLP's surface on every cell (no steps, no residual): the first hit."""
    dense: torch.Tensor
    """(rows, cols) float32 `height` on the region's cells, `smooth` elsewhere: what the search reads."""

    def cell_coordinates(self, xy: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(N,) fractional column and row of global x, y (cell centres at integers)."""
        x0, y0 = self.grid.origin_xy
        return (xy[:, 0] - x0) / self.grid.resolution_m, (y0 - xy[:, 1]) / self.grid.resolution_m

    def raster_at(self, raster: torch.Tensor, xy: torch.Tensor) -> torch.Tensor:
        """(N,) float64 bilinear samples of a (rows, cols) raster of the grid (clamped to its edge) at x, y."""
        col, row = self.cell_coordinates(xy)
        return bilinear(raster, row, col)

    def corners(self, xy: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """The four cells around each x, y: their (N, 4) vertex ids (-1 outside the region or the grid), their
        (N, 4) bilinear weights (differentiable in x, y) and their (N, 4) row-major cell indices (clamped to the
        grid)."""
        col, row = self.cell_coordinates(xy)
        c0, r0 = col.detach().floor(), row.detach().floor()
        fc, fr = col - c0, row - r0
        rows = torch.stack([r0, r0, r0 + 1, r0 + 1], dim=1).long()
        cols = torch.stack([c0, c0 + 1, c0, c0 + 1], dim=1).long()
        weights = torch.stack([(1 - fr) * (1 - fc), (1 - fr) * fc, fr * (1 - fc), fr * fc], dim=1)
        on_grid = (rows >= 0) & (rows < self.grid.rows) & (cols >= 0) & (cols < self.grid.cols)
        flat = rows.clamp(0, self.grid.rows - 1) * self.grid.cols + cols.clamp(0, self.grid.cols - 1)
        ids = torch.where(on_grid, self.vertex_id.reshape(-1)[flat], -1)
        return ids, weights, flat

    def height_at(self, xy: torch.Tensor) -> torch.Tensor:
        """(N,) float64 full height, differentiable in the vertices' heights: the smooth surface at corners
        outside the region."""
        ids, weights, flat = self.corners(xy)
        outside = self.dense.reshape(-1)[flat].double()
        corner_z = torch.where(ids >= 0, self.height[ids.clamp(min=0)].double(), outside)
        return (weights.double() * corner_z).sum(dim=1)

    def attributes_at(self, xy: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(N, C) bilinear attributes and (N,) whether all four corners are region vertices."""
        ids, weights, _ = self.corners(xy)
        inside = (ids >= 0).all(dim=1)
        values = (weights.float()[..., None] * self.attributes[ids.clamp(min=0)]).sum(dim=1)
        return values, inside


def vertex_cells_flat(grid: SurfaceGrid) -> torch.Tensor:
    """(V,) long: each vertex's cell as a row-major index into the grid."""
    rows, cols = grid.vertex_cells()
    return torch.as_tensor(rows * grid.cols + cols)


def dense_heights(smooth: torch.Tensor, vertex_cells: torch.Tensor, height: torch.Tensor) -> torch.Tensor:
    """(rows, cols) float32: the (V,) `height` on the vertices' cells, the `smooth` raster elsewhere (detached)."""
    dense = smooth.detach().float().clone()
    dense.view(-1)[vertex_cells] = height.detach().float()
    return dense


def bilinear(raster: torch.Tensor, row: torch.Tensor, col: torch.Tensor) -> torch.Tensor:
    """(N,) bilinear samples of a (rows, cols) raster at fractional rows and columns, clamped to its edge, in the
    precision of `row` (float64 from float64 rows, else float32)."""
    row = row.clamp(0, raster.shape[0] - 1)
    col = col.clamp(0, raster.shape[1] - 1)
    r0 = row.floor().long().clamp(max=raster.shape[0] - 2)
    c0 = col.floor().long().clamp(max=raster.shape[1] - 2)
    fr, fc = row - r0, col - c0
    z = raster.to(row.dtype)
    top = z[r0, c0] * (1 - fc) + z[r0, c0 + 1] * fc
    bottom = z[r0 + 1, c0] * (1 - fc) + z[r0 + 1, c0 + 1] * fc
    return top * (1 - fr) + bottom * fr


@dataclass(frozen=True, eq=False)
class Hits:
    """Where a batch of rays meets the field."""

    xy: torch.Tensor
    """(N, 2) float64 global x, y of the hits (differentiable in the field's heights)."""
    valid: torch.Tensor
    """(N,) bool: the ray came down onto the field within range."""


def first_crossings(
    field: HeightField,
    origin: torch.Tensor,
    direction: torch.Tensor,
    search_m: tuple[float, float],
    samples: int,
) -> tuple[torch.Tensor, torch.Tensor]:
    """(N,) float64 ray lengths of each ray's first crossing of the full field (detached) and whether one was
    found. `origin` (N, 3) float64 global metres, `direction` (N, 3) float64 unit rays; `search_m` (below,
    above) the smooth surface bounds the heights searched (the steps and the residual lie within them)."""
    down = direction[:, 2] < -SLOPE_FLOOR
    dz = torch.where(down, direction[:, 2], torch.full_like(direction[:, 2], -1.0))
    with torch.no_grad():
        length = torch.zeros_like(dz)
        for _ in range(FIXED_POINT_ITERATIONS):
            ground = field.raster_at(field.smooth, (origin + length[:, None] * direction)[:, :2])
            length = ((ground - origin[:, 2]) / dz).clamp(min=0)
        below, above = search_m
        near = ((ground + above - origin[:, 2]) / dz).clamp(min=0)
        far = ((ground - below - origin[:, 2]) / dz).clamp(min=0)
        fractions = torch.linspace(0, 1, samples, dtype=torch.float64, device=origin.device)
        lengths = near[:, None] + (far - near)[:, None] * fractions
        points = origin[:, None, :] + lengths[..., None] * direction[:, None, :]
        col, row = field.cell_coordinates(points[..., :2].reshape(-1, 2))
        field_z = bilinear(field.dense, row.float(), col.float()).reshape(lengths.shape)
        gap = points[..., 2] - field_z
        under = gap <= 0
        found = under.any(dim=1) & down
        first = under.int().argmax(dim=1)
        before = (first - 1).clamp(min=0)
        rows = torch.arange(len(dz), device=origin.device)
        g0, g1 = gap[rows, before], gap[rows, first]
        t0, t1 = lengths[rows, before], lengths[rows, first]
        share = torch.where(g0 > g1, g0 / (g0 - g1).clamp(min=1e-12), torch.zeros_like(g0))
        return t0 + share.clamp(0, 1) * (t1 - t0), found


def cast_rays(
    field: HeightField,
    origin: torch.Tensor,
    direction: torch.Tensor,
    max_range_m: float,
    search_m: tuple[float, float],
    samples: int,
) -> Hits:
    """Each ray's first hit on the field (steps 1-3 of the module docstring)."""
    length, found = first_crossings(field, origin, direction, search_m, samples)
    xy = origin[:, :2] + length[:, None] * direction[:, :2]
    gap = origin[:, 2] + length * direction[:, 2] - field.height_at(xy)
    with torch.no_grad():
        res = field.grid.resolution_m
        offsets = torch.tensor(
            [[res, 0.0], [-res, 0.0], [0.0, res], [0.0, -res]], dtype=xy.dtype, device=xy.device
        )
        around = field.raster_at(field.dense, (xy[:, None, :] + offsets).reshape(-1, 2)).reshape(-1, 4)
        slope_x = (around[:, 0] - around[:, 1]) / (2 * res)
        slope_y = (around[:, 2] - around[:, 3]) / (2 * res)
        rate = direction[:, 2] - slope_x * direction[:, 0] - slope_y * direction[:, 1]
        rate = rate.clamp(max=-SLOPE_FLOOR)
    length = length - gap / rate
    hit_xy = origin[:, :2] + length[:, None] * direction[:, :2]
    valid = found & (length.detach() > 0) & (length.detach() < max_range_m)
    return Hits(hit_xy, valid)
