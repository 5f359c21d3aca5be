"""Vectors rasterised into the element-mask network's targets, and site rasters into its input, on one grid.

The grid is the site's raster resampled to the network's resolution (`MaskModelConfig.resolution_m`): pixel
(col, row) of the grid covers the same ground as the site raster's pixels scaled by the resolution ratio.
Dividers and boundaries are drawn as bands `line_width_m` wide along their polylines (continuous across dash
gaps: a dashed lane line is one divider); crosswalks are their filled rings. The same drawing serves generator
ground truth and annotators' corrections, so a correction teaches the network the geometry it should draw.
"""

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from annotations.schema import POLYGON_CLASSES
from cama_pipeline.semantics import Semantic
from models.vma.element_masks.config import MaskModelConfig
from models.vma.rasters import SiteRasters, model_input
from models.vma.vectors import CLASSES, Vector

SUBPIXEL_BITS = 4
"""Fractional bits of the polyline coordinates handed to OpenCV's drawing (1/16 px)."""


@dataclass(frozen=True, eq=False)
class MaskGrid:
    """A site at the network's resolution: its input channels and the mapping to global metres."""

    image: np.ndarray
    """(C, H, W) float32 network input."""
    observed: np.ndarray
    """(H, W) bool: cells some camera saw (any semantic class)."""
    origin_xy: tuple[float, float]
    """Global metres of grid pixel (0, 0)'s centre."""
    resolution_m: float

    def pixel_from_global(self, xy: np.ndarray) -> np.ndarray:
        """Global x, y to fractional grid (col, row); rows run towards -y as in every BEV raster."""
        xy = np.asarray(xy, dtype=np.float64)
        col = (xy[:, 0] - self.origin_xy[0]) / self.resolution_m
        row = (self.origin_xy[1] - xy[:, 1]) / self.resolution_m
        return np.column_stack([col, row])

    @property
    def shape(self) -> tuple[int, int]:
        """(height, width) in grid pixels."""
        return (int(self.image.shape[1]), int(self.image.shape[2]))


def mask_grid(rasters: SiteRasters, config: MaskModelConfig) -> MaskGrid:
    """The network input of a site's rasters on the grid at `config.resolution_m`."""
    image = model_input(rasters, config.resolution_m)
    observed = cv2.resize(
        (rasters.semantic != int(Semantic.UNOBSERVED)).astype(np.uint8),
        (image.shape[2], image.shape[1]),
        interpolation=cv2.INTER_NEAREST,
    ).astype(bool)
    # both grids share the raster's top-left corner; rows run towards -y
    x0, y0 = rasters.origin_xy
    corner = (x0 - 0.5 * rasters.resolution_m, y0 + 0.5 * rasters.resolution_m)
    half = 0.5 * config.resolution_m
    return MaskGrid(image, observed, (corner[0] + half, corner[1] - half), config.resolution_m)


def element_masks(vectors: Sequence[Vector], grid: MaskGrid, config: MaskModelConfig) -> np.ndarray:
    """(K, H, W) float32 target masks of `vectors` on `grid`, one per class of `CLASSES`."""
    height, width = grid.shape
    masks = np.zeros((len(CLASSES), height, width), np.uint8)
    for vector in vectors:
        # OpenCV draws pixel centres at integer coordinates, as the grid's (col, row)
        points = np.rint(grid.pixel_from_global(vector.points) * (1 << SUBPIXEL_BITS)).astype(np.int32)
        layer = masks[CLASSES.index(vector.cls)]
        if vector.closed:
            cv2.fillPoly(layer, [points], 1, lineType=cv2.LINE_8, shift=SUBPIXEL_BITS)
        else:
            cv2.polylines(layer, [points], False, 1, 1, lineType=cv2.LINE_8, shift=SUBPIXEL_BITS)
    half_width_px = 0.5 * config.line_width_m / grid.resolution_m
    for cls in CLASSES:
        layer = masks[CLASSES.index(cls)]
        if cls not in POLYGON_CLASSES and layer.any():
            # the centre lines widened to bands: cells within half the width of a line's cells
            layer[:] = cv2.distanceTransform(1 - layer, cv2.DIST_L2, 5) <= half_width_px
    return masks.astype(np.float32)
