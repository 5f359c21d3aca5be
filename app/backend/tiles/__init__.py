"""BEV raster tiles: display colouring, cached tile pyramids, safe tile lookup and elevation queries."""

from app.backend.tiles.access import (
    TileRequestError,
    UnknownLayerError,
    elevation_at,
    pyramid_info,
    tile_file,
)
from app.backend.tiles.layers import Legend
from app.backend.tiles.pyramid import PyramidInfo, PyramidLevel, build_pyramid, build_site_pyramids

__all__ = [
    "Legend",
    "PyramidInfo",
    "PyramidLevel",
    "TileRequestError",
    "UnknownLayerError",
    "build_pyramid",
    "build_site_pyramids",
    "elevation_at",
    "pyramid_info",
    "tile_file",
]
