"""Sites: register from a synthetic folder or a georeference, list, extent, layers and counts."""

import json
import logging
import threading
from collections.abc import Sequence
from pathlib import Path
from weakref import WeakKeyDictionary

from sqlalchemy import Engine, func, select
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session

from annotations.schema import Georeference
from app.backend.clock import utc_now
from app.backend.crud.site_sources import camera_sources
from app.backend.data_roots import data_folder
from app.backend.errors import ConflictError, InvalidInputError, NotFoundError
from app.backend.models import Element, Site
from app.backend.schemas import Extent, SiteCreate
from cama_pipeline.bev import RasterGeoreference, georeference_path, read_georeference

logger = logging.getLogger(__name__)

LAYER_SUFFIXES = (".png", ".npy", ".tif", ".tiff")
_EXTENTS: "WeakKeyDictionary[Engine, dict[int, Extent]]" = WeakKeyDictionary()
"""Site extents per database engine: a site's georeference never changes once registered, so every edit's
extent check need not load the site again."""
_EXTENTS_LOCK = threading.Lock()


def _read_synthetic(folder: Path) -> tuple[Georeference, Path]:
    """Georeference (with the site origin) and raster folder of a `cama synth` site folder (messages name the
    files relative to it: the folder's place on the server is not the caller's business)."""
    manifest_path = folder / "manifest.json"
    geo_path = georeference_path(folder / "ground_truth" / "bev")
    for path in (manifest_path, geo_path):
        if not path.is_file():
            name = path.relative_to(folder).as_posix()
            raise InvalidInputError("synthetic_dir", f"{name} not found; is this a `cama synth` folder?")
    try:
        origin = json.loads(manifest_path.read_text(encoding="utf-8"))["config"]["site_origin_xy"]
        origin_xy = (float(origin[0]), float(origin[1]))
        georeference = Georeference.of(read_georeference(geo_path.parent), site_origin_xy=origin_xy)
    except (OSError, KeyError, IndexError, TypeError, ValueError) as error:
        logger.warning("%s: unreadable site: %s", folder, error)
        name = geo_path.relative_to(folder).as_posix()
        raise InvalidInputError("synthetic_dir", f"unreadable site: manifest.json or {name}") from error
    return georeference, geo_path.parent


def create_site(*, session: Session, site_in: SiteCreate, roots: Sequence[Path]) -> Site:
    """Register a site from folders inside the data `roots` (resolved), with its camera sources
    (`site_sources`); InvalidInputError naming the field for a folder that is missing, unreadable or outside
    them, or a bad georeference."""
    folder = None
    if site_in.synthetic_dir is not None:
        folder = data_folder(site_in.synthetic_dir, roots=roots, field="synthetic_dir")
        georeference, raster_dir = _read_synthetic(folder)
    else:
        raster = site_in.georeference.raster()  # type: ignore[union-attr]  # checked by SiteCreate
        georeference = Georeference.of(raster, site_origin_xy=site_in.site_origin_xy)  # type: ignore[arg-type]
        raster_dir = data_folder(site_in.raster_dir or "", roots=roots, field="raster_dir")
    sources = camera_sources(site_in, raster_dir=raster_dir, synthetic_dir=folder, roots=roots)
    origin_xy = georeference.site_origin_xy
    site = Site(
        name=site_in.name,
        site_origin_x=origin_xy[0],
        site_origin_y=origin_xy[1],
        georeference=georeference.to_json(),
        raster_dir=str(raster_dir),
        created_at=utc_now(),
        dataset_root=None if sources.dataset_root is None else str(sources.dataset_root),
        workspace_dir=None if sources.workspace_dir is None else str(sources.workspace_dir),
        recon_site_id=sources.recon_site_id,
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
    geo = RasterGeoreference.from_json(site.georeference, source=f"site {site.id}")
    resolution = geo.resolution
    x0 = geo.origin_xy[0] - site.site_origin_x
    y0 = geo.origin_xy[1] - site.site_origin_y
    return Extent(
        xmin=x0 - resolution / 2,
        xmax=x0 + (geo.width - 0.5) * resolution,
        ymin=y0 - (geo.height - 0.5) * resolution,
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
