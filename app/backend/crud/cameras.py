"""What the camera endpoints read from the database: a site's camera sources, an element's neighbours."""

import logging
from collections.abc import Sequence
from pathlib import Path

from shapely import LineString
from sqlalchemy import select
from sqlalchemy.orm import Session

from annotations.schema import Georeference
from app.backend.cameras import SiteSources
from app.backend.data_roots import inside
from app.backend.models import Element, Site
from cama_pipeline.bev import RasterGeoreference

logger = logging.getLogger(__name__)

NEIGHBOUR_RADIUS_M = 30.0
"""Other live elements this close (2D) to an element are drawn faintly beside it."""
MAX_NEIGHBOURS = 200
"""At most this many neighbours are projected (the nearest)."""


def _allowed(value: str | None, roots: Sequence[Path], what: str, site_id: int) -> Path | None:
    """A stored folder when it still lies inside the data roots (they may have changed since registration)."""
    if value is None:
        return None
    path = Path(value)
    if not inside(path.resolve(), roots):
        logger.warning("site %d: %s %s is outside the data roots now; not used", site_id, what, path)
        return None
    return path


def site_sources(site: Site, roots: Sequence[Path]) -> SiteSources:
    """Where the site's cameras come from (its registration), folders outside the data roots left out."""
    return SiteSources(
        site_id=site.id,
        georeference=Georeference.of(
            RasterGeoreference.from_json(site.georeference, source=f"site {site.id}"),
            site_origin_xy=(site.site_origin_x, site.site_origin_y),
        ),
        raster_dir=Path(site.raster_dir),
        dataset_root=_allowed(site.dataset_root, roots, "dataset_root", site.id),
        workspace_dir=_allowed(site.workspace_dir, roots, "workspace_dir", site.id),
        recon_site_id=site.recon_site_id,
    )


def element_neighbours(
    *, session: Session, element: Element, radius_m: float = NEIGHBOUR_RADIUS_M
) -> list[tuple[int, str, list[list[float]]]]:
    """(id, class, points) of the other live elements of the site within `radius_m` of the element, nearest
    first, at most MAX_NEIGHBOURS."""
    query = select(Element).where(
        Element.site_id == element.site_id,
        Element.deleted.is_(False),
        Element.id != element.id,
        Element.xmax >= element.xmin - radius_m,
        Element.xmin <= element.xmax + radius_m,
        Element.ymax >= element.ymin - radius_m,
        Element.ymin <= element.ymax + radius_m,
    )
    line = LineString(element.points)
    near = []
    for other in session.scalars(query):
        distance = line.distance(LineString(other.points))
        if distance <= radius_m:
            near.append((distance, other.id, other.cls, other.points))
    near.sort(key=lambda item: (item[0], item[1]))
    return [(element_id, cls, points) for _, element_id, cls, points in near[:MAX_NEIGHBOURS]]
