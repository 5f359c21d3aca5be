"""Serving-side reads: safe tile lookup in a site's cache and elevation queries at a point."""

import logging
import math
from pathlib import Path

import numpy as np

from app.backend.tiles.pyramid import PyramidInfo, ensure_empty_tile, read_pyramid_info, tile_path
from cama_pipeline.bev import LAYER_NAMES, LayerName, RasterGeoreference

logger = logging.getLogger(__name__)


class UnknownLayerError(KeyError):
    """The layer name is not a known layer, or its pyramid has not been built (HTTP 404)."""


class TileRequestError(ValueError):
    """z/x/y are not non-negative integers inside the pyramid (HTTP 404/422)."""


def _check_index(name: str, value: object, bound: int) -> int:
    """`value` as an int in [0, bound); TileRequestError otherwise (bools and floats included)."""
    if isinstance(value, bool) or not isinstance(value, int | np.integer):
        raise TileRequestError(f"tile {name} must be an integer, got {value!r}")
    if not 0 <= int(value) < bound:
        raise TileRequestError(f"tile {name}={value} is outside [0, {bound})")
    return int(value)


def pyramid_info(cache_dir: Path, layer: str) -> PyramidInfo:
    """The complete pyramid of a known layer; UnknownLayerError when the name is unknown or not built."""
    if not isinstance(layer, str) or layer not in LAYER_NAMES:
        raise UnknownLayerError(f"unknown raster layer {layer!r}; known: {', '.join(LAYER_NAMES)}")
    known: LayerName = layer  # type: ignore[assignment]  # narrowed by the membership test above
    info = read_pyramid_info(cache_dir, known)
    if info is None:
        raise UnknownLayerError(f"layer {layer}: no tile pyramid built in {cache_dir}")
    return info


def tile_file(cache_dir: Path, layer: str, z: int, x: int, y: int) -> Path:
    """Path of tile (z, x, y), or of the shared transparent tile where the level has nothing to show.

    x and y may range over the level's full 2**z square (an XYZ client may ask beyond the raster);
    anything else raises TileRequestError, and an unknown layer UnknownLayerError.
    """
    info = pyramid_info(cache_dir, layer)
    z = _check_index("z", z, info.max_zoom + 1)
    x = _check_index("x", x, 2**z)
    y = _check_index("y", y, 2**z)
    root = Path(cache_dir).resolve()
    path = tile_path(root, info.layer, z, x, y).resolve()
    if not path.is_relative_to(root):  # cannot happen with validated ints; defence in depth
        raise TileRequestError(f"tile path {path} escapes the cache directory {root}")
    if path.is_file():
        return path
    return ensure_empty_tile(root, info.tile_size)


def elevation_at(elevation: np.ndarray, georef: RasterGeoreference, x: float, y: float) -> float | None:
    """Bilinear elevation (m) at global metres (x, y); None outside the raster or when a used cell is NaN."""
    if not (math.isfinite(x) and math.isfinite(y)):
        raise ValueError(f"elevation query at non-finite point ({x}, {y})")
    height, width = elevation.shape[:2]
    col, row = (float(v) for v in georef.pixel_from_global([x, y])[0])
    if not (0.0 <= col <= width - 1 and 0.0 <= row <= height - 1):
        return None
    c0, r0 = min(int(col), max(width - 2, 0)), min(int(row), max(height - 2, 0))
    fc, fr = col - c0, row - r0
    total = 0.0
    for dr, wr in ((0, 1.0 - fr), (1, fr)):
        for dc, wc in ((0, 1.0 - fc), (1, fc)):
            weight = wr * wc
            if weight == 0.0:
                continue  # a cell with no weight does not contribute (also keeps edge queries in range)
            value = float(elevation[r0 + dr, c0 + dc])
            if not math.isfinite(value):
                return None
            total += weight * value
    return total
