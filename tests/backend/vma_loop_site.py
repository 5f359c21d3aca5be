"""A drawn raster site on the backend test georeference (200 x 200 px at 0.5 m) and a tiny VMA registry.

Site metres (origin 1000, 2000): a road from y 30 to 70 m with curbs at both edges and a solid divider at
y 50 m, all along x. The folder is laid out like a generated site (`ground_truth/bev/` rasters and
`ground_truth/vector_map.json` in global metres), so it serves as a validation site too.
"""

from pathlib import Path

import cv2
import numpy as np

from cama_pipeline.io import atomic_write_image, atomic_write_json
from cama_pipeline.semantics import Semantic
from models.vma.checkpoint import promote, save_version
from models.vma.config import ModelConfig
from models.vma.model import VmaNet
from tests.backend.backend_helpers import GEOREFERENCE, ORIGIN_XY

TINY = ModelConfig(
    resolution_m=1.0, patch_px=64, num_queries=4, num_points=4, dim=16, decoder_layers=1, heads=2
)
"""A model that trains and infers in well under a second on the 100 m test site."""
ROAD_Y = (30.0, 70.0)
DIVIDER_Y = 50.0


def row_of(y_site: float) -> int:
    """Raster row of a site y (row 0 is site y 100)."""
    return round((100.0 - y_site) / GEOREFERENCE["resolution"])


def write_site(folder: Path) -> Path:
    """Write the drawn site; returns its raster folder (`ground_truth/bev`)."""
    semantic = np.zeros((200, 200), np.uint8)
    semantic[row_of(ROAD_Y[1]) : row_of(ROAD_Y[0])] = int(Semantic.ROAD)
    for y in ROAD_Y:
        semantic[row_of(y) - 1 : row_of(y) + 1] = int(Semantic.CURB)
    semantic[row_of(DIVIDER_Y) - 1 : row_of(DIVIDER_Y) + 1, 10:190] = int(Semantic.LANE_MARKING)
    colours = np.array(
        [[60, 110, 70], [80, 80, 80], [160, 160, 160], [230, 230, 230], [235, 235, 235]], np.uint8
    )
    bev = folder / "ground_truth" / "bev"
    atomic_write_image(bev / "semantic.png", semantic)
    atomic_write_image(bev / "photometric.png", cv2.cvtColor(colours[semantic], cv2.COLOR_RGB2BGR))
    atomic_write_json(bev / "georeference.json", GEOREFERENCE)

    def line(y: float, x0: float, x1: float) -> list[list[float]]:
        return [[ORIGIN_XY[0] + x0, ORIGIN_XY[1] + y], [ORIGIN_XY[0] + x1, ORIGIN_XY[1] + y]]

    vectors = [
        {"id": "b0", "class": "boundary", "points": line(ROAD_Y[0], 0.0, 99.5)},
        {"id": "b1", "class": "boundary", "points": line(ROAD_Y[1], 0.0, 99.5)},
        {"id": "d0", "class": "divider", "points": line(DIVIDER_Y, 5.0, 95.0)},
    ]
    atomic_write_json(folder / "ground_truth" / "vector_map.json", {"elements": vectors})
    return bev


def write_registry(folder: Path) -> Path:
    """A registry whose promoted v0001 is an untrained tiny model (it saw no site)."""
    unseen = {"sites": [], "seen_sites": [], "seen_folders": []}
    promote(folder, save_version(folder, VmaNet(TINY), {"metrics": {}, "data": unseen}).name)
    return folder
