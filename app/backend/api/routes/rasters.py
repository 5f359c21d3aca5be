"""BEV rasters of a site: layers with pyramid and legend, XYZ tiles (built once, cached on disk), elevation."""

import logging
import math
import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated

from fastapi import APIRouter, Depends, Query, Request
from fastapi.responses import FileResponse, Response

from app.backend import crud
from app.backend.api.deps import CurrentUser, IdPath, SessionDep, SettingsDep
from app.backend.errors import InvalidInputError, NotFoundError
from app.backend.models import Site
from app.backend.schemas_quality import ElevationPublic, LayerPublic
from app.backend.tiles import (
    PyramidInfo,
    TileRequestError,
    UnknownLayerError,
    build_site_pyramids,
    elevation_at,
    tile_file,
)
from cama_pipeline.bev import LayerName, RasterGeoreference, is_raster_folder, read_layer

logger = logging.getLogger(__name__)
router = APIRouter(prefix="/sites/{site_id}", tags=["rasters"])
_STATE_LOCK = threading.Lock()
TILE_CACHE_CONTROL = "private, max-age=31536000, immutable"
"""Tiles change only with their pyramid's fingerprint (in the ETag), so browsers keep them; `private`: they are
answers to authenticated requests, which no shared cache may keep (every other API answer is `no-store`)."""
PNG: dict[int | str, dict[str, object]] = {
    200: {"content": {"image/png": {}}, "description": "An RGBA PNG tile."},
    304: {"description": "Not modified (If-None-Match matched the ETag)."},
}


@dataclass
class TileCache:
    """Pyramids built in this process per site; one lock per site so concurrent first requests build once."""

    built: dict[int, dict[LayerName, PyramidInfo]] = field(default_factory=dict)
    locks: dict[int, threading.Lock] = field(default_factory=dict)
    lock: threading.Lock = field(default_factory=threading.Lock)

    def site_lock(self, site_id: int) -> threading.Lock:
        """The build lock of one site."""
        with self.lock:
            return self.locks.setdefault(site_id, threading.Lock())


def get_tile_cache(request: Request) -> TileCache:
    """The app's tile cache, made on first use."""
    with _STATE_LOCK:
        cache = getattr(request.app.state, "tile_cache", None)
        if cache is None:
            cache = request.app.state.tile_cache = TileCache()
    return cache


TileCacheDep = Annotated[TileCache, Depends(get_tile_cache)]


def cache_dir(data_dir: Path, site_id: int) -> Path:
    """Where a site's pyramids are stored: `<data_dir>/tiles/<site_id>`."""
    return Path(data_dir).resolve() / "tiles" / str(site_id)


def ensure_pyramids(site: Site, cache: TileCache, data_dir: Path) -> dict[LayerName, PyramidInfo]:
    """The site's pyramids, built on first use (a no-op stat check when already on disk from an earlier run).

    A raster folder without layer files has no layers; unreadable rasters give a 422 naming the file.
    """
    with cache.site_lock(site.id):
        if site.id in cache.built:
            return cache.built[site.id]
        raster_dir = Path(site.raster_dir)
        if not is_raster_folder(raster_dir):
            logger.warning("site %d: %s has no raster georeference; no raster layers", site.id, raster_dir)
            infos: dict[LayerName, PyramidInfo] = {}
        else:
            try:
                infos = build_site_pyramids(raster_dir, cache_dir(data_dir, site.id))
            except FileNotFoundError:
                infos = {}
            except ValueError as error:
                raise InvalidInputError(
                    "raster_dir", f"site {site.id}: rasters cannot be tiled: {error}"
                ) from None
        cache.built[site.id] = infos
        return infos


def _tile_url(site_id: int, info: PyramidInfo) -> str:
    """The XYZ URL template of a layer, versioned by its fingerprint."""
    return f"/api/sites/{site_id}/tiles/{info.layer}/{{z}}/{{x}}/{{y}}.png?v={info.fingerprint}"


@router.get("/layers", response_model=list[LayerPublic])
def list_layers(
    site_id: IdPath, session: SessionDep, settings: SettingsDep, cache: TileCacheDep, _user: CurrentUser
) -> list[LayerPublic]:
    """The site's raster layers with pyramid levels, georeference and legend (pyramids built on first call)."""
    site = crud.get_site(session=session, site_id=site_id)
    infos = ensure_pyramids(site, cache, settings.data_dir)
    return [
        LayerPublic(name=name, tile_url=_tile_url(site_id, info), pyramid=info)
        for name, info in infos.items()
    ]


@router.get("/tiles/{layer}/{z}/{x}/{y}.png", response_class=FileResponse, response_model=None, responses=PNG)
def read_tile(
    site_id: IdPath,
    layer: str,
    z: int,
    x: int,
    y: int,
    request: Request,
    session: SessionDep,
    settings: SettingsDep,
    cache: TileCacheDep,
    _user: CurrentUser,
) -> Response:
    """One RGBA PNG tile (XYZ, y down); transparent where nothing was observed; 404 outside the pyramid."""
    site = crud.get_site(session=session, site_id=site_id)
    infos = ensure_pyramids(site, cache, settings.data_dir)
    info = infos.get(layer)  # type: ignore[call-overload]  # any str: unknown names just miss
    if info is None:
        raise NotFoundError(f"site {site_id} has no raster layer {layer!r}; it has {sorted(infos)}")
    try:
        path = tile_file(cache_dir(settings.data_dir, site_id), layer, z, x, y)
    except (UnknownLayerError, TileRequestError) as error:
        raise NotFoundError(f"tile {layer}/{z}/{x}/{y}: {str(error).strip(chr(39))}") from None
    etag = f'"{info.fingerprint}-{z}-{x}-{y}"'
    headers = {"Cache-Control": TILE_CACHE_CONTROL, "ETag": etag}
    if request.headers.get("if-none-match") == etag:
        return Response(status_code=304, headers=headers)
    return FileResponse(path, media_type="image/png", headers=headers)


@router.get("/elevation", response_model=ElevationPublic)
def read_elevation(
    site_id: IdPath,
    session: SessionDep,
    _user: CurrentUser,
    x: Annotated[float, Query(description="Site metres.")],
    y: Annotated[float, Query(description="Site metres.")],
) -> ElevationPublic:
    """Bilinear elevation at a site point; null outside the raster or where the ground was unobserved."""
    if not (math.isfinite(x) and math.isfinite(y)):
        raise InvalidInputError("x" if not math.isfinite(x) else "y", f"must be finite, got ({x}, {y})")
    site = crud.get_site(session=session, site_id=site_id)
    try:
        elevation = read_layer(Path(site.raster_dir), "elevation", mmap=True)
    except FileNotFoundError:
        raise NotFoundError(f"site {site_id} has no elevation raster") from None
    except ValueError as error:
        raise InvalidInputError("raster_dir", f"site {site_id}: {error}") from None
    georef = RasterGeoreference.from_json(site.georeference, source=f"site {site_id}")
    if elevation.shape[:2] != (georef.height, georef.width):
        raise InvalidInputError(
            "raster_dir", f"site {site_id}: elevation shape {elevation.shape} does not match the georeference"
        )
    global_xy = (x + site.site_origin_x, y + site.site_origin_y)
    value = elevation_at(elevation, georef, *global_xy)
    return ElevationPublic(xy=(x, y), global_xy=global_xy, elevation_m=value)
