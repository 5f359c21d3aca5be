"""A hand-made semantic raster with a kerbed road edge, a road edge without a kerb and an unobserved strip, and
boundaries along each (shared by the kerb evidence, Lanelet2 and export command tests)."""

import numpy as np

from annotations import AnnotationSet, Georeference, MapElement
from cama_pipeline.semantics import Semantic
from tests.annotations.annotation_helpers import SITE_ORIGIN_XY, element_kwargs

KERB_RESOLUTION_M = 0.1
KERB_SIZE_PX = 200
KERB_GEOREF = Georeference(
    site_origin_xy=SITE_ORIGIN_XY,
    origin_xy=(SITE_ORIGIN_XY[0], SITE_ORIGIN_XY[1] + 20.0),
    resolution=KERB_RESOLUTION_M,
    width=KERB_SIZE_PX,
    height=KERB_SIZE_PX,
)
"""200 x 200 cells at 0.1 m; cell (row, col)'s centre is at site x = 0.1 col, y = 20 - 0.1 row."""
ROAD_Y = (6.0, 12.0)
"""The road lies between these site y (a lane marking along y 9); grass below it, a kerb then a sidewalk above."""
CURB_TOP_Y = 12.3
UNOBSERVED_FROM_Y = 14.5
KERB_Y, BORDER_Y, HIDDEN_Y, INSIDE_Y = 12.0, 6.0, 17.0, 8.0
"""The boundaries of `kerb_set`: on the kerb, on the road's grass edge, in the unobserved strip, inside the road."""


def kerb_raster(*, curb_until_x: float = 20.0) -> np.ndarray:
    """The scene's (H, W) uint8 semantic raster; the kerb runs from x 0 to `curb_until_x` (sidewalk beyond)."""
    rows, cols = np.mgrid[0:KERB_SIZE_PX, 0:KERB_SIZE_PX]
    x, y = cols * KERB_RESOLUTION_M, 20.0 - rows * KERB_RESOLUTION_M
    raster = np.full(x.shape, int(Semantic.BACKGROUND), dtype=np.uint8)  # grass and sidewalk
    raster[(y >= ROAD_Y[0] - 1e-9) & (y < ROAD_Y[1] - 1e-9)] = int(Semantic.ROAD)
    raster[np.abs(y - 9.0) < 0.1] = int(Semantic.LANE_MARKING)
    raster[(y >= ROAD_Y[1] - 1e-9) & (y < CURB_TOP_Y - 1e-9) & (x < curb_until_x)] = int(Semantic.CURB)
    raster[y >= UNOBSERVED_FROM_Y] = int(Semantic.UNOBSERVED)
    return raster


def boundary(element_id: str, y: float, x0: float = 1.0, x1: float = 18.0) -> MapElement:
    """A straight boundary along site y from x0 to x1 (direction +x: the road of `kerb_raster` on its right
    for the kerb, on its left for the grass edge)."""
    points = [[x0, y], [(x0 + x1) / 2, y], [x1, y]]
    return MapElement(**element_kwargs(id=element_id, points_2d=points, **{"class": "boundary"}))


def kerb_set() -> AnnotationSet:
    """The four boundaries over `kerb_raster` and a divider (which gets no verdict)."""
    divider = MapElement(**element_kwargs(id="div", points_2d=[[1.0, 9.0], [18.0, 9.0]]))
    boundaries = [
        boundary("kerb", KERB_Y),
        boundary("border", BORDER_Y),
        boundary("hidden", HIDDEN_Y),
        boundary("inside", INSIDE_Y),
    ]
    return AnnotationSet(site_id="s", georeference=KERB_GEOREF, elements=[divider, *boundaries])
