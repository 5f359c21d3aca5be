"""The job kinds that need no model: `lift` (2D -> 3D through the elevation raster), and what every site job
reads (`site_annotations`, `read_elevation`).

The export kind lives in `jobs/export.py`, the VMA loop's kinds (`retrain`, `refresh_proposals`) in `jobs/vma.py`.
"""

import logging
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pydantic import BaseModel, Field
from sqlalchemy import select
from sqlalchemy.orm import Session

from annotations.lift import DEFAULT_MAX_SPACING_M, DEFAULT_SEARCH_RADIUS_M, lift_points
from annotations.schema import AnnotationSet, Georeference, MapElement
from app.backend.jobs.runner import JobContext, JobKind, JobResult
from app.backend.models import Element, Site
from app.backend.schemas import STRICT
from cama_pipeline.bev import RasterGeoreference, read_layer

logger = logging.getLogger(__name__)

LIFTED_FILE = "lifted.json"
_FLAG_REPORT_LIMIT = 10


class LiftParams(BaseModel):
    """Parameters of a `lift` job (see `annotations.lift.lift_points`)."""

    model_config = STRICT
    max_spacing_m: float = Field(default=DEFAULT_MAX_SPACING_M, gt=0.0, le=100.0)
    """Densify polylines to at most this spacing before lifting, metres."""
    search_radius_m: float = Field(default=DEFAULT_SEARCH_RADIUS_M, ge=0.0, le=100.0)
    """How far an unobserved cell may borrow the nearest observed elevation, metres."""


def _map_element(row: Element) -> MapElement:
    """The `annotations` view of a stored element."""
    return MapElement.model_validate(
        {
            "id": str(row.id),
            "cls": row.cls,
            "points_2d": row.points,
            "source": row.source,
            "confidence": row.confidence,
            "review_state": row.state,
            "version": row.version,
            "author": row.author,
            "created_at": row.created_at,
            "updated_at": row.created_at if row.updated_at < row.created_at else row.updated_at,
        }
    )


def site_annotations(context: JobContext) -> tuple[AnnotationSet, Path, str]:
    """The site's live elements as an annotation set, its raster folder and its name (one short session)."""
    with context.session() as session:
        site = session.get(Site, context.site_id)
        if site is None:
            raise ValueError(f"site {context.site_id}: not found")
        return _annotations_of(session, site)


def every_site_annotations(context: JobContext) -> list[tuple[AnnotationSet, Path, str]]:
    """`site_annotations` of every site in the database, the job's own first (one short session)."""
    with context.session() as session:
        sites = session.scalars(select(Site).order_by(Site.id)).all()
        ordered = sorted(sites, key=lambda site: site.id != context.site_id)
        return [_annotations_of(session, site) for site in ordered]


def _annotations_of(session: Session, site: Site) -> tuple[AnnotationSet, Path, str]:
    rows = session.scalars(
        select(Element).where(Element.site_id == site.id, Element.deleted.is_(False)).order_by(Element.id)
    ).all()
    raster = RasterGeoreference.from_json(site.georeference, source=f"site {site.name}")
    georef = Georeference.of(raster, site_origin_xy=(site.site_origin_x, site.site_origin_y))
    annotations = AnnotationSet(
        site_id=site.name, georeference=georef, elements=[_map_element(row) for row in rows]
    )
    return annotations, Path(site.raster_dir), site.name


def read_elevation(raster_dir: Path, georef: Georeference) -> np.ndarray:
    """The site's elevation raster; FileNotFoundError / ValueError naming the file when unusable."""
    elevation = read_layer(raster_dir, "elevation")
    if elevation.shape != georef.shape:
        raise ValueError(
            f"{raster_dir}: elevation shape {elevation.shape} != the site's georeference (height, width) "
            f"{georef.shape}"
        )
    return np.asarray(elevation, dtype=np.float64)


@dataclass(frozen=True)
class Lifted:
    """An annotation set lifted through an elevation raster, and the elements left without 3D points."""

    annotations: AnnotationSet
    flagged: list[tuple[str, int]]
    """(element id, vertices without observed elevation near) of each element left unlifted."""


def lift_elements(
    annotations: AnnotationSet,
    elevation: np.ndarray,
    *,
    max_spacing_m: float = DEFAULT_MAX_SPACING_M,
    search_radius_m: float = DEFAULT_SEARCH_RADIUS_M,
    on_element: Callable[[int], None] | None = None,
) -> Lifted:
    """Each element with its 3D points through `elevation` (`annotations.lift.lift_points`); one with a vertex
    far from any observed cell stays as it is and is listed. `on_element(done)` after each element."""
    georef = annotations.georeference
    elements: list[MapElement] = []
    flagged: list[tuple[str, int]] = []
    for index, element in enumerate(annotations.elements):
        result = lift_points(
            element.points_2d,
            elevation,
            georef,
            max_spacing_m=max_spacing_m,
            search_radius_m=search_radius_m,
        )
        if result.ok:
            points = [(x, y, z) for x, y, z in result.points_3d.tolist()]
            elements.append(element.with_changes(points_3d=points))
        else:
            elements.append(element)
            flagged.append((element.id, len(result.flagged)))
        if on_element is not None:
            on_element(index + 1)
    lifted = AnnotationSet(site_id=annotations.site_id, georeference=georef, elements=elements)
    return Lifted(lifted, flagged)


def run_lift(context: JobContext, params: LiftParams) -> JobResult:
    """Lift every live element; the lifted set goes to `lifted.json`, flagged vertices to the message."""
    annotations, raster_dir, _name = site_annotations(context)
    elevation = read_elevation(raster_dir, annotations.georeference)
    total = len(annotations.elements)
    context.report(0.05, f"lifting {total} elements", force=True)
    lifted = lift_elements(
        annotations,
        elevation,
        max_spacing_m=params.max_spacing_m,
        search_radius_m=params.search_radius_m,
        on_element=lambda done: context.report(0.05 + 0.9 * done / max(total, 1)),
    )
    out = context.workdir / LIFTED_FILE
    lifted.annotations.write_json(out)
    flagged = [f"element {element_id} ({count} vertices)" for element_id, count in lifted.flagged]
    message = f"lifted {total - len(flagged)} of {total} elements"
    if flagged:
        shown = ", ".join(flagged[:_FLAG_REPORT_LIMIT])
        more = f" and {len(flagged) - _FLAG_REPORT_LIMIT} more" if len(flagged) > _FLAG_REPORT_LIMIT else ""
        vertices = sum(count for _id, count in lifted.flagged)
        message += (
            f"; {vertices} vertices flagged (no observed elevation within "
            f"{params.search_radius_m} m), left without 3D points: {shown}{more}"
        )
    return JobResult(out, message)


JOB_KINDS: dict[str, JobKind] = {
    "lift": JobKind(LiftParams, run_lift, "Lift every live element to 3D through the elevation raster."),
}
"""The kinds a new runner starts with (the runner copies it)."""
