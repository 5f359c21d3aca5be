"""Hand-drawn raster sites for the VMA tests (rasters, georeference and vector map written like the generator's)."""

from pathlib import Path

import cv2
import numpy as np

from cama_pipeline.io import atomic_write_image, atomic_write_json
from cama_pipeline.semantics import Semantic

ORIGIN_XY = (500.0, 800.0)
RESOLUTION_M = 0.1
WIDTH_PX, HEIGHT_PX = 600, 400


def pixel(x_m: float, y_m: float) -> tuple[int, int]:
    """(col, row) of a point given in metres from the raster's top-left pixel centre (y down)."""
    return round(x_m / RESOLUTION_M), round(y_m / RESOLUTION_M)


def global_xy(x_m: float, y_m: float) -> list[float]:
    """Global coordinates of a point given like `pixel`'s."""
    return [ORIGIN_XY[0] + x_m, ORIGIN_XY[1] - y_m]


def drawn_semantic() -> tuple[np.ndarray, list[dict]]:
    """Road y 12..28 m with curbs, a dashed divider at y = 20 m (3 m dashes, 6 m gaps) stopping at a crossing at x 30..34 m."""
    semantic = np.zeros((HEIGHT_PX, WIDTH_PX), np.uint8)
    semantic[pixel(0, 12)[1] : pixel(0, 28)[1]] = int(Semantic.ROAD)
    for y in (12.0, 28.0):
        row = pixel(0, y)[1]
        semantic[row - 1 : row + 1] = int(Semantic.CURB)
    row = pixel(0, 20)[1]
    for x0 in np.arange(1.0, 60.0, 9.0):
        if 29.0 < x0 + 3 and x0 < 35.0:
            continue
        semantic[row - 1 : row + 1, pixel(x0, 0)[0] : pixel(min(x0 + 3, 59.9), 0)[0]] = int(
            Semantic.LANE_MARKING
        )
    for y0 in np.arange(12.5, 27.5, 1.0):
        semantic[pixel(0, y0)[1] : pixel(0, y0 + 0.5)[1], pixel(30, 0)[0] : pixel(34, 0)[0]] = int(
            Semantic.CROSSWALK
        )
    vectors = [
        {"id": "b0", "class": "boundary", "points": [global_xy(0, 12), global_xy(59.9, 12)]},
        {"id": "b1", "class": "boundary", "points": [global_xy(0, 28), global_xy(59.9, 28)]},
        {"id": "d0", "class": "divider", "points": [global_xy(1, 20), global_xy(22, 20)]},
        {"id": "d1", "class": "divider", "points": [global_xy(37, 20), global_xy(58, 20)]},
        {
            "id": "c0",
            "class": "ped_crossing",
            "points": [
                global_xy(30, 12.5),
                global_xy(34, 12.5),
                global_xy(34, 27.5),
                global_xy(30, 27.5),
                global_xy(30, 12.5),
            ],
            "closed": True,
        },
    ]
    return semantic, vectors


def write_raster_site(
    folder: Path, semantic: np.ndarray, vectors: list[dict], georeference: dict | None = None
) -> Path:
    """Write `<folder>/ground_truth/{bev/semantic.png, bev/photometric.png, bev/georeference.json, vector_map.json}`."""
    bev = folder / "ground_truth" / "bev"
    colours = np.array(
        [[60, 110, 70], [80, 80, 80], [160, 160, 160], [230, 230, 230], [235, 235, 235]], np.uint8
    )
    photometric = colours[np.minimum(semantic, 4)]
    atomic_write_image(bev / "semantic.png", semantic)
    atomic_write_image(bev / "photometric.png", cv2.cvtColor(photometric, cv2.COLOR_RGB2BGR))
    geo = georeference or {
        "origin_xy": list(ORIGIN_XY),
        "resolution": RESOLUTION_M,
        "width": int(semantic.shape[1]),
        "height": int(semantic.shape[0]),
        "frame": "global",
        "row_axis": "-y",
        "col_axis": "+x",
    }
    atomic_write_json(bev / "georeference.json", geo)
    atomic_write_json(folder / "ground_truth" / "vector_map.json", {"elements": vectors})
    return folder


def hand_drawn_site(folder: Path) -> Path:
    """The drawn site written to `folder`."""
    semantic, vectors = drawn_semantic()
    return write_raster_site(folder, semantic, vectors)
