"""Sites: register from a synthetic folder or a georeference, list, extent, layers and counts."""

import json
import logging
import threading
from collections.abc import Sequence
from pathlib import Path
from typing import Any
from weakref import WeakKeyDictionary

from sqlalchemy import Engine, func, select
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session

from annotations.schema import Georeference
from app.backend.clock import utc_now
from app.backend.data_roots import data_folder
from app.backend.errors import ConflictError, InvalidInputError, NotFoundError
from app.backend.models import Element, Site
from app.backend.schemas import Extent, SiteCreate

logger = logging.getLogger(__name__)

LAYER_SUFFIXES = (".png", ".npy", ".tif", ".tiff")
_EXTENTS: "WeakKeyDictionary[Engine, dict[int, Extent]]" = WeakKeyDictionary()
"""Site extents per database engine: a site's georeference never changes once registered, so every edit's
extent check need not load the site again."""
_EXTENTS_LOCK = threading.Lock()


def _read_synthetic(folder: Path) -> tuple[tuple[float, float], dict[str, Any], Path]:
    """Site origin, raster georeference and raster folder of a `cama synth` site folder (messages name the
    files relative to it: the folder's place on the server is not the caller's business)."""
    manifest_path = folder / "manifest.json"
    geo_path = folder / "ground_truth" / "bev" / "georeference.json"
    for path in (manifest_path, geo_path):
        if not path.is_file():
            name = path.relative_to(folder).as_posix()
            raise InvalidInputError("synthetic_dir", f"{name} not found; is this a `cama synth` folder?")
    try:
        origin = json.loads(manifest_path.read_text(encoding="utf-8"))["config"]["site_origin_xy"]
        origin_xy = (float(origin[0]), float(origin[1]))
        georeference = Georeference.from_raster_file(geo_path, site_origin_xy=origin_xy)
    except (OSError, KeyError, IndexError, TypeError, ValueError) as error:
        logger.warning("%s: unreadable site: %s", folder, error)
        raise InvalidInputError(
            "synthetic_dir", "unreadable site: manifest.json or ground_truth/bev/georeference.json"
        ) from error
    return origin_xy, georeference.raster_json(), geo_path.parent


def create_site(*, session: Session, site_in: SiteCreate, roots: Sequence[Path]) -> Site:
    """Register a site from folders inside the data `roots` (resolved); InvalidInputError naming the field for
    a folder that is missing, unreadable or outside them, or a bad georeference."""
    if site_in.synthetic_dir is not None:
        folder = data_folder(site_in.synthetic_dir, roots=roots, field="synthetic_dir")
        origin_xy, geo, raster_dir = _read_synthetic(folder)
    else:
        origin_xy = site_in.site_origin_xy  # type: ignore[assignment]  # checked by SiteCreate
        geo = site_in.georeference.model_dump()  # type: ignore[union-attr]
        raster_dir = data_folder(site_in.raster_dir or "", roots=roots, field="raster_dir")
    site = Site(
        name=site_in.name,
        site_origin_x=origin_xy[0],
        site_origin_y=origin_xy[1],
        georeference=Georeference.from_raster_json(geo, site_origin_xy=origin_xy).raster_json(),
        raster_dir=str(raster_dir),
        created_at=utc_now(),
    )
    session.add(site)
    try:
        session.commit()
    except IntegrityError:
        session.rollback()
        raise ConflictError(f"name: a site named {site_in.name!r} already exists") from None
    logger.info("registered site %s from %s", site.name, raster_dir)
    return site


def get_site(*, session: Session, site_id: int) -> Site:
    """The site with this id; NotFoundError otherwise."""
    site = session.get(Site, site_id)
    if site is None:
        raise NotFoundError(f"site {site_id} not found")
    return site


def cached_extent(*, session: Session, site_id: int) -> Extent:
    """The site's extent (NotFoundError for an unknown site), loaded once per engine."""
    engine = session.get_bind()
    with _EXTENTS_LOCK:
        extent = _EXTENTS.get(engine, {}).get(site_id)  # type: ignore[arg-type]
    if extent is None:
        extent = site_extent(get_site(session=session, site_id=site_id))
        with _EXTENTS_LOCK:
            _EXTENTS.setdefault(engine, {})[site_id] = extent  # type: ignore[arg-type]
    return extent


def list_sites(*, session: Session) -> list[Site]:
    """All sites by id."""
    return list(session.scalars(select(Site).order_by(Site.id)))


def site_extent(site: Site) -> Extent:
    """The raster's footprint in site metres (pixel edges, rows growing with -y)."""
    geo = site.georeference
    resolution = float(geo["resolution"])
    x0 = float(geo["origin_xy"][0]) - site.site_origin_x
    y0 = float(geo["origin_xy"][1]) - site.site_origin_y
    return Extent(
        xmin=x0 - resolution / 2,
        xmax=x0 + (int(geo["width"]) - 0.5) * resolution,
        ymin=y0 - (int(geo["height"]) - 0.5) * resolution,
        ymax=y0 + resolution / 2,
    )


def site_layers(site: Site) -> list[str]:
    """Names of the raster layers present in the site's raster folder (and its parent, e.g. elevation)."""
    names: set[str] = set()
    for folder in (Path(site.raster_dir), Path(site.raster_dir).parent):
        if folder.is_dir():
            names.update(p.stem for p in folder.iterdir() if p.suffix.lower() in LAYER_SUFFIXES)
    return sorted(names)


def site_counts(*, session: Session, site_id: int) -> tuple[dict[str, int], dict[str, int]]:
    """Counts of live (not deleted) elements by review state and by class."""
    live = (Element.site_id == site_id, Element.deleted.is_(False))
    by_state = session.execute(select(Element.state, func.count()).where(*live).group_by(Element.state))
    by_class = session.execute(select(Element.cls, func.count()).where(*live).group_by(Element.cls))
    return {k: int(v) for k, v in by_state.all()}, {k: int(v) for k, v in by_class.all()}
