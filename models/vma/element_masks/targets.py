"""Vectors rasterised into the element-mask network's targets on the grid of its input.

The grid is the site's raster resampled to the network's resolution (`models.vma.patches.site_grid` at
`MaskModelConfig.resolution_m`, the MapTR-style model's grid too). Dividers and boundaries are drawn as bands `line_width_m` wide along their polylines (continuous across dash
gaps: a dashed lane line is one divider); crosswalks are their filled rings. The same drawing serves generator
ground truth and annotators' corrections, so a correction teaches the network the geometry it should draw.
"""

from collections.abc import Sequence

import cv2
import numpy as np

from annotations.schema import POLYGON_CLASSES
from models.vma.element_masks.config import MaskModelConfig
from models.vma.patches import SiteGrid
from models.vma.vectors import CLASSES, Vector

SUBPIXEL_BITS = 4
"""Fractional bits of the polyline coordinates handed to OpenCV's drawing (1/16 px)."""


def element_masks(vectors: Sequence[Vector], grid: SiteGrid, config: MaskModelConfig) -> np.ndarray:
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
