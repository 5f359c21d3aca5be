"""Tile pyramids of BEV layers, built once with OpenCV and cached on disk (this module owns the format).

Layout under a site's cache directory:
    <cache>/empty.png                      shared fully transparent tile (served for empty tiles)
    <cache>/<layer>/<z>/<x>/<y>.png        RGBA PNG tiles, all tile_size x tile_size: the right and bottom edge
                                           tiles are padded with transparent pixels (a plain XYZ client draws
                                           every tile into a full square, so a cut tile would be stretched);
                                           tiles with nothing visible are not written
    <cache>/<layer>/pyramid.json           PyramidInfo, written last: its presence means the pyramid is complete
Level z has the raster downsampled by 2**(max_zoom - z); level 0 is the first to fit in one tile. Tile (x, y)
of level z covers level pixels [x * tile, (x + 1) * tile) x [y * tile, (y + 1) * tile), column x, row y.
The full-resolution level is cut from the source raster window by window; each coarser tile is made from its
four child tiles (nearest for semantic ids, premultiplied-alpha INTER_AREA otherwise), so nothing bigger than
a 512 x 512 mosaic is ever held.
"""

import hashlib
import json
import logging
import math
import shutil
from pathlib import Path

import cv2
import numpy as np
from pydantic import BaseModel, ConfigDict, ValidationError

from app.backend.tiles.layers import LayerStyle, Legend, Resampling, check_layer, layer_style
from cama_pipeline.bev import (
    LAYER_FILES,
    LAYER_NAMES,
    LayerName,
    RasterGeoreference,
    layer_path,
    read_georeference,
    read_layer,
)
from cama_pipeline.io import atomic_write_bytes
from cama_pipeline.progress import StageProgress

logger = logging.getLogger(__name__)

TILE_SIZE = 256
FORMAT_VERSION = 2
"""Bump when tile rendering changes, so cached pyramids are rebuilt."""
INFO_NAME = "pyramid.json"
EMPTY_TILE_NAME = "empty.png"
_PROGRESS_MIN_TILES = 64


class PyramidLevel(BaseModel):
    """Size of one zoom level in pixels and tiles."""

    model_config = ConfigDict(frozen=True)

    z: int
    width: int
    height: int
    cols: int
    rows: int


class PyramidInfo(BaseModel):
    """A layer's complete pyramid (the content of `pyramid.json`)."""

    model_config = ConfigDict(frozen=True)

    format_version: int = FORMAT_VERSION
    layer: LayerName
    tile_size: int
    max_zoom: int
    width: int
    height: int
    levels: tuple[PyramidLevel, ...]
    georeference: RasterGeoreference
    legend: Legend
    fingerprint: str


def pyramid_levels(width: int, height: int, tile_size: int = TILE_SIZE) -> tuple[PyramidLevel, ...]:
    """Levels 0..max_zoom for a width x height raster; level 0 fits in one tile."""
    if width < 1 or height < 1 or tile_size < 1:
        raise ValueError(f"raster {width} x {height} with tile size {tile_size}: all must be >= 1")
    max_zoom = max(0, math.ceil(math.log2(max(width, height) / tile_size)))
    levels = []
    for z in range(max_zoom + 1):
        factor = 2 ** (max_zoom - z)
        w, h = -(-width // factor), -(-height // factor)
        levels.append(PyramidLevel(z=z, width=w, height=h, cols=-(-w // tile_size), rows=-(-h // tile_size)))
    return tuple(levels)


def layer_dir(cache_dir: Path, layer: LayerName) -> Path:
    """Directory of one layer's pyramid."""
    return Path(cache_dir) / layer


def tile_path(cache_dir: Path, layer: LayerName, z: int, x: int, y: int) -> Path:
    """Where tile (z, x, y) of a layer is (or would be) stored; no validation (see access.tile_file)."""
    return layer_dir(cache_dir, layer) / str(z) / str(x) / f"{y}.png"


def read_pyramid_info(cache_dir: Path, layer: LayerName) -> PyramidInfo | None:
    """The layer's complete pyramid description, or None when absent or unreadable (then it is rebuilt)."""
    path = layer_dir(cache_dir, layer) / INFO_NAME
    try:
        return PyramidInfo.model_validate(json.loads(path.read_text(encoding="utf-8")))
    except FileNotFoundError:
        return None
    except (json.JSONDecodeError, ValidationError) as error:
        logger.warning("%s: unreadable pyramid description, it will be rebuilt: %s", path, error)
        return None


def array_fingerprint(raster: np.ndarray) -> str:
    """Content hash of a raster, hashed in row bands so a memory-mapped raster is never copied whole."""
    digest = hashlib.blake2b(f"{raster.shape}:{raster.dtype.str}".encode(), digest_size=16)
    band = max(1, (64 << 20) // max(1, raster[:1].nbytes))
    for row in range(0, raster.shape[0], band):
        digest.update(np.ascontiguousarray(raster[row : row + band]).data)
    return digest.hexdigest()


def file_fingerprint(path: Path) -> str:
    """Cheap fingerprint of a source file: name, size and modification time."""
    stat = Path(path).stat()
    return f"{Path(path).name}:{stat.st_size}:{stat.st_mtime_ns}"


def _full_fingerprint(source: str, georef: RasterGeoreference, tile_size: int) -> str:
    """Fingerprint of everything a pyramid depends on: source, georeference, tile size, format."""
    text = f"v{FORMAT_VERSION}|{tile_size}|{georef.model_dump_json()}|{source}"
    return hashlib.blake2b(text.encode(), digest_size=16).hexdigest()


def _encode_png(bgra: np.ndarray, path: Path) -> None:
    """Write a BGRA tile as an RGBA PNG atomically."""
    ok, encoded = cv2.imencode(".png", bgra)
    if not ok:
        raise ValueError(f"could not encode tile of shape {bgra.shape}: {path}")
    atomic_write_bytes(path, encoded.tobytes())


def ensure_empty_tile(cache_dir: Path, tile_size: int = TILE_SIZE) -> Path:
    """The shared transparent tile of a cache directory, written once."""
    path = Path(cache_dir) / EMPTY_TILE_NAME
    if not path.is_file():
        _encode_png(np.zeros((tile_size, tile_size, 4), dtype=np.uint8), path)
    return path


def downsample_half(bgra: np.ndarray, resampling: Resampling) -> np.ndarray:
    """Halve a BGRA mosaic (odd sizes round up): nearest, or area averaging with premultiplied alpha."""
    if resampling == "nearest":
        return np.ascontiguousarray(bgra[::2, ::2])
    height, width = bgra.shape[:2]
    alpha = bgra[:, :, 3:4].astype(np.float32) / 255.0
    premultiplied = np.concatenate([bgra[:, :, :3] * alpha, bgra[:, :, 3:4]], axis=2).astype(np.float32)
    padded = cv2.copyMakeBorder(premultiplied, 0, height % 2, 0, width % 2, cv2.BORDER_REPLICATE)
    small = cv2.resize(padded, (padded.shape[1] // 2, padded.shape[0] // 2), interpolation=cv2.INTER_AREA)
    out_alpha = small[:, :, 3:4]
    colour = np.where(out_alpha > 0, small[:, :, :3] * 255.0 / np.maximum(out_alpha, 1e-6), 0.0)
    return np.clip(np.concatenate([colour, out_alpha], axis=2) + 0.5, 0, 255).astype(np.uint8)


def _write_tile(
    cache_dir: Path, layer: LayerName, z: int, x: int, y: int, bgra: np.ndarray, tile_size: int
) -> None:
    """Store a tile padded to a full square unless nothing in it is visible (the shared empty tile stands
    for it then)."""
    if not bgra[:, :, 3].any():
        return
    full = np.zeros((tile_size, tile_size, 4), dtype=np.uint8)
    full[: bgra.shape[0], : bgra.shape[1]] = bgra
    _encode_png(full, tile_path(cache_dir, layer, z, x, y))


def _read_tile(
    cache_dir: Path, layer: LayerName, z: int, x: int, y: int, shape: tuple[int, int]
) -> np.ndarray:
    """The part of a stored tile that covers raster pixels (`shape`) as BGRA; transparent when it was empty."""
    path = tile_path(cache_dir, layer, z, x, y)
    tile = cv2.imread(str(path), cv2.IMREAD_UNCHANGED) if path.is_file() else None
    return tile[: shape[0], : shape[1]] if tile is not None else np.zeros((*shape, 4), dtype=np.uint8)


def _parent_tile(
    cache_dir: Path, style: LayerStyle, child: PyramidLevel, x: int, y: int, tile_size: int
) -> np.ndarray:
    """Tile (x, y) of level child.z - 1, made from its (up to) four children."""
    x0, y0 = 2 * x * tile_size, 2 * y * tile_size
    width, height = min(2 * tile_size, child.width - x0), min(2 * tile_size, child.height - y0)
    mosaic = np.zeros((height, width, 4), dtype=np.uint8)
    for cy in (2 * y, 2 * y + 1):
        for cx in (2 * x, 2 * x + 1):
            if cx >= child.cols or cy >= child.rows:
                continue
            c0, r0 = cx * tile_size - x0, cy * tile_size - y0
            shape = (min(tile_size, height - r0), min(tile_size, width - c0))
            tile = _read_tile(cache_dir, style.name, child.z, cx, cy, shape)
            mosaic[r0 : r0 + shape[0], c0 : c0 + shape[1]] = tile
    return downsample_half(mosaic, style.resampling)


def _write_levels(
    cache_dir: Path, style: LayerStyle, raster: np.ndarray, levels: tuple[PyramidLevel, ...], tile_size: int
) -> None:
    """Write every tile: the finest level from raster windows, then each coarser level from its children."""
    total = sum(level.cols * level.rows for level in levels)
    shown = total >= _PROGRESS_MIN_TILES
    with StageProgress(f"tiles {style.name}", logger=logger, enabled=shown) as progress:
        task = progress.add_task(total=total)
        finest = levels[-1]
        for y in range(finest.rows):
            for x in range(finest.cols):
                window = raster[y * tile_size : (y + 1) * tile_size, x * tile_size : (x + 1) * tile_size]
                _write_tile(cache_dir, style.name, finest.z, x, y, style.render(window), tile_size)
                progress.advance(task)
        for child in reversed(levels[1:]):
            parent = levels[child.z - 1]
            for y in range(parent.rows):
                for x in range(parent.cols):
                    tile = _parent_tile(cache_dir, style, child, x, y, tile_size)
                    _write_tile(cache_dir, style.name, parent.z, x, y, tile, tile_size)
                    progress.advance(task)


def _up_to_date(cache_dir: Path, layer: LayerName, fingerprint: str) -> PyramidInfo | None:
    """The cached pyramid when it was built from exactly this source, else None."""
    info = read_pyramid_info(cache_dir, layer)
    return info if info is not None and info.fingerprint == fingerprint else None


def build_pyramid(
    layer_name: LayerName,
    raster: np.ndarray,
    georef: RasterGeoreference,
    cache_dir: Path,
    *,
    overwrite: bool = False,
    source_fingerprint: str | None = None,
    tile_size: int = TILE_SIZE,
) -> PyramidInfo:
    """Build (or reuse, when up to date) one layer's tile pyramid; `source_fingerprint` defaults to a content hash."""
    if layer_name not in LAYER_NAMES:
        raise ValueError(f"unknown raster layer {layer_name!r}; known: {', '.join(LAYER_NAMES)}")
    geo = georef.as_raster()
    check_layer(layer_name, raster, (geo.height, geo.width))
    fingerprint = _full_fingerprint(source_fingerprint or array_fingerprint(raster), geo, tile_size)
    cached = None if overwrite else _up_to_date(cache_dir, layer_name, fingerprint)
    if cached is not None:
        logger.info("tiles %s: up to date in %s", layer_name, cache_dir)
        return cached
    target = layer_dir(cache_dir, layer_name)
    (target / INFO_NAME).unlink(missing_ok=True)  # incomplete from here on
    if target.is_dir():
        shutil.rmtree(target)  # drop tiles of the previous source, which may now be empty
    style = layer_style(layer_name, raster)
    levels = pyramid_levels(geo.width, geo.height, tile_size)
    ensure_empty_tile(cache_dir, tile_size)
    _write_levels(Path(cache_dir), style, raster, levels, tile_size)
    info = PyramidInfo(
        layer=layer_name,
        tile_size=tile_size,
        max_zoom=len(levels) - 1,
        width=geo.width,
        height=geo.height,
        levels=levels,
        georeference=geo,
        legend=style.legend,
        fingerprint=fingerprint,
    )
    atomic_write_bytes(target / INFO_NAME, info.model_dump_json(indent=2).encode("utf-8"))
    logger.info("tiles %s: %d levels written to %s", layer_name, len(levels), target)
    return info


def build_site_pyramids(
    bev_dir: Path, cache_dir: Path, *, overwrite: bool = False
) -> dict[LayerName, PyramidInfo]:
    """Pyramids of every layer present in a BEV directory; up-to-date layers are not even read."""
    bev_dir = Path(bev_dir)
    georef = read_georeference(bev_dir)
    infos: dict[LayerName, PyramidInfo] = {}
    for name in LAYER_NAMES:
        path = layer_path(bev_dir, name)
        if not path.is_file():
            continue
        source = file_fingerprint(path)
        cached = (
            None if overwrite else _up_to_date(cache_dir, name, _full_fingerprint(source, georef, TILE_SIZE))
        )
        if cached is not None:
            infos[name] = cached
            continue
        raster = read_layer(bev_dir, name, mmap=True)
        infos[name] = build_pyramid(
            name, raster, georef, cache_dir, overwrite=True, source_fingerprint=source
        )
    if not infos:
        raise FileNotFoundError(f"{bev_dir}: no BEV layer files ({', '.join(LAYER_FILES.values())})")
    return infos
