"""The site's raster grid and mesh vertices: one vertex per cell centre of the road region.

The extent comes from the site's own surface points (never from any ground truth): their bounding box
grown by the region radius, snapped to whole multiples of the resolution. The road region is the cells
within the radius of a surface point (the trajectory strip and the SfM road points).
"""

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from cama_pipeline.bev import RasterGeoreference


@dataclass(frozen=True, eq=False)
class SurfaceGrid:
    """A BEV grid (DESIGN.md convention: pixel (0, 0) centre at `origin_xy`, rows grow with -y) and its
    road-region vertices."""

    origin_xy: tuple[float, float]
    resolution_m: float
    rows: int
    cols: int
    vertex_id: np.ndarray
    """(rows, cols) int64: the vertex index of each cell, -1 outside the road region."""

    @property
    def vertex_count(self) -> int:
        return int((self.vertex_id >= 0).sum())

    def vertex_cells(self) -> tuple[np.ndarray, np.ndarray]:
        """(row, col) of every vertex, in vertex order."""
        rows, cols = np.nonzero(self.vertex_id >= 0)
        return rows, cols

    def xy_of_cells(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """(N, 2) global x, y of cell centres."""
        return np.stack(
            [self.origin_xy[0] + cols * self.resolution_m, self.origin_xy[1] - rows * self.resolution_m],
            axis=1,
        )

    def vertex_xy(self) -> np.ndarray:
        """(V, 2) global x, y of every vertex."""
        return self.xy_of_cells(*self.vertex_cells())

    def cell_of_xy(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Nearest cell (row, col) of global x, y (may fall outside the grid)."""
        cols = np.round((xy[:, 0] - self.origin_xy[0]) / self.resolution_m).astype(np.int64)
        rows = np.round((self.origin_xy[1] - xy[:, 1]) / self.resolution_m).astype(np.int64)
        return rows, cols

    def in_region(self, xy: np.ndarray) -> np.ndarray:
        """(N,) whether each global x, y falls on a cell of the road region."""
        rows, cols = self.cell_of_xy(xy)
        inside = (rows >= 0) & (rows < self.rows) & (cols >= 0) & (cols < self.cols)
        found = np.zeros(len(xy), bool)
        found[inside] = self.vertex_id[rows[inside], cols[inside]] >= 0
        return found

    def georeference(self) -> RasterGeoreference:
        """The rasters' georeference."""
        return RasterGeoreference(
            origin_xy=self.origin_xy, resolution=self.resolution_m, width=self.cols, height=self.rows
        )


def road_grid(points_xy: np.ndarray, resolution_m: float, radius_m: float) -> SurfaceGrid:
    """The grid around `points_xy` (N, 2) with vertices on the cells within `radius_m` of a point."""
    margin = radius_m + resolution_m
    x0 = np.floor((points_xy[:, 0].min() - margin) / resolution_m) * resolution_m
    y0 = np.ceil((points_xy[:, 1].max() + margin) / resolution_m) * resolution_m
    cols = int(np.ceil((points_xy[:, 0].max() + margin - x0) / resolution_m)) + 1
    rows = int(np.ceil((y0 - points_xy[:, 1].min() + margin) / resolution_m)) + 1
    grid = SurfaceGrid((float(x0), float(y0)), resolution_m, rows, cols, np.zeros((0, 0), np.int64))
    r, c = grid.cell_of_xy(points_xy)
    seeds = np.ones((rows, cols), bool)
    seeds[r, c] = False
    region = ndimage.distance_transform_edt(seeds, sampling=resolution_m) <= radius_m
    vertex_id = np.full((rows, cols), -1, np.int64)
    vertex_id[region] = np.arange(int(region.sum()))
    return SurfaceGrid(grid.origin_xy, resolution_m, rows, cols, vertex_id)
