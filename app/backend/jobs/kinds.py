"""The job kinds that need no model: `lift` (2D -> 3D through the elevation raster) and `export` (CAMA or MapTR).

The VMA loop's kinds (`retrain`, `refresh_proposals`) live in `jobs/vma.py`.
"""

import logging
import os
import shutil
import zipfile
from pathlib import Path
from typing import Annotated, Literal, Self

import numpy as np
from pydantic import AfterValidator, BaseModel, Field, model_validator
from sqlalchemy import select

from annotations.cama_format import export_cama
from annotations.lift import DEFAULT_MAX_SPACING_M, DEFAULT_SEARCH_RADIUS_M, lift_points
from annotations.maptr_format import export_maptr
from annotations.poses import coarse_pose
from annotations.schema import AnnotationSet, Georeference, MapElement
from app.backend.data_roots import data_folder_validator
from app.backend.jobs.runner import JobContext, JobKind, JobResult
from app.backend.models import Element, Site
from app.backend.schemas import STRICT
from cama_pipeline.bev import RasterGeoreference, read_layer
from cama_pipeline.data import Dataset, load_dataset

logger = logging.getLogger(__name__)

LIFTED_FILE = "lifted.json"
EXPORT_ZIP = "export.zip"
EXPORT_FOLDER = "export"
PARTIAL_SUFFIX = ".partial"
_FLAG_REPORT_LIMIT = 10


class LiftParams(BaseModel):
    """Parameters of a `lift` job (see `annotations.lift.lift_points`)."""

    model_config = STRICT
    max_spacing_m: float = Field(default=DEFAULT_MAX_SPACING_M, gt=0.0, le=100.0)
    """Densify polylines to at most this spacing before lifting, metres."""
    search_radius_m: float = Field(default=DEFAULT_SEARCH_RADIUS_M, ge=0.0, le=100.0)
    """How far an unobserved cell may borrow the nearest observed elevation, metres."""


class ExportParams(BaseModel):
    """Parameters of an `export` job: the CAMA release layout, or MapTR vectors (needs the data set)."""

    model_config = STRICT
    format: Literal["cama", "maptr"] = "cama"
    dataset_root: Annotated[str | None, AfterValidator(data_folder_validator)] = Field(
        default=None, max_length=4096
    )
    """Data set folder (tables, poses) the MapTR samples are cut from; required for `maptr`. It must lie inside
    the server's data roots; stored resolved."""

    @model_validator(mode="after")
    def _maptr_needs_dataset(self) -> Self:
        if self.format == "maptr" and not self.dataset_root:
            raise ValueError("dataset_root: required for format 'maptr'")
        return self


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


def run_lift(context: JobContext, params: LiftParams) -> JobResult:
    """Lift every live element; the lifted set goes to `lifted.json`, flagged vertices to the message."""
    annotations, raster_dir, _name = site_annotations(context)
    georef = annotations.georeference
    elevation = read_elevation(raster_dir, georef)
    total = len(annotations.elements)
    context.report(0.05, f"lifting {total} elements", force=True)
    lifted: list[MapElement] = []
    flagged: list[str] = []
    flagged_vertices = 0
    for index, element in enumerate(annotations.elements):
        result = lift_points(
            element.points_2d,
            elevation,
            georef,
            max_spacing_m=params.max_spacing_m,
            search_radius_m=params.search_radius_m,
        )
        if result.ok:
            points = [(x, y, z) for x, y, z in result.points_3d.tolist()]
            lifted.append(element.with_changes(points_3d=points))
        else:
            lifted.append(element)
            flagged_vertices += len(result.flagged)
            flagged.append(f"element {element.id} ({len(result.flagged)} vertices)")
        context.report(0.05 + 0.9 * (index + 1) / max(total, 1))
    out = context.workdir / LIFTED_FILE
    AnnotationSet(site_id=annotations.site_id, georeference=georef, elements=lifted).write_json(out)
    message = f"lifted {total - len(flagged)} of {total} elements"
    if flagged:
        shown = ", ".join(flagged[:_FLAG_REPORT_LIMIT])
        more = f" and {len(flagged) - _FLAG_REPORT_LIMIT} more" if len(flagged) > _FLAG_REPORT_LIMIT else ""
        message += (
            f"; {flagged_vertices} vertices flagged (no observed elevation within "
            f"{params.search_radius_m} m), left without 3D points: {shown}{more}"
        )
    return JobResult(out, message)


def zip_folder(folder: Path, archive: Path, context: JobContext) -> Path:
    """Zip every file under `folder` (names relative to it) into `archive`, written atomically."""
    files = sorted(path for path in folder.rglob("*") if path.is_file())
    partial = archive.with_name(archive.name + PARTIAL_SUFFIX)
    with zipfile.ZipFile(partial, "w", compression=zipfile.ZIP_DEFLATED) as bundle:
        for index, path in enumerate(files):
            bundle.write(path, path.relative_to(folder).as_posix())
            context.report(0.8 + 0.19 * (index + 1) / len(files))
    os.replace(partial, archive)
    return archive


def _dataset(root: str) -> Dataset:
    """The data set of a MapTR export; a ValueError that names no path or folder content when unusable (the
    job's message is shown to API callers; the server log has the details)."""
    try:
        return load_dataset(Path(root))
    except (OSError, ValueError) as error:  # DatasetError is a ValueError
        logger.warning("export: data set %s unusable: %s", root, error)
        raise ValueError(
            "dataset_root: not a readable data set (tables and poses); see the server log"
        ) from None


def run_export(context: JobContext, params: ExportParams) -> JobResult:
    """Export the live elements to `<job>/export/` and zip it into `<job>/export.zip`."""
    annotations, raster_dir, name = site_annotations(context)
    context.report(0.2, f"exporting {len(annotations.elements)} elements ({params.format})", force=True)
    folder = context.workdir / EXPORT_FOLDER
    shutil.rmtree(folder, ignore_errors=True)
    if params.format == "cama":
        try:
            elevation: np.ndarray | None = read_elevation(raster_dir, annotations.georeference)
        except (FileNotFoundError, ValueError) as error:
            logger.warning("site %s: exporting without elevation: %s", name, error)
            elevation = None
        export_cama(annotations, context.workdir, name=folder.name, elevation=elevation)
    else:
        dataset = _dataset(params.dataset_root or "")
        context.report(0.5, "building MapTR samples", force=True)
        # the job has no workspace yet, so it writes the logged poses and says so (pose_source "coarse")
        export_maptr(annotations, dataset, folder / "maptr.json", poses=coarse_pose)
    context.report(0.8, "packing the archive", force=True)
    archive = zip_folder(folder, context.workdir / EXPORT_ZIP, context)
    return JobResult(archive, f"exported {len(annotations.elements)} elements of {name} ({params.format})")


def clean_export(workdir: Path) -> None:
    """Remove an export's unzipped folder and a half-written archive; the finished `export.zip` stays."""
    shutil.rmtree(workdir / EXPORT_FOLDER, ignore_errors=True)
    (workdir / (EXPORT_ZIP + PARTIAL_SUFFIX)).unlink(missing_ok=True)


JOB_KINDS: dict[str, JobKind] = {
    "lift": JobKind(LiftParams, run_lift, "Lift every live element to 3D through the elevation raster."),
    "export": JobKind(
        ExportParams,
        run_export,
        "Export the live elements (cama, or maptr with a data set).",
        cleanup=clean_export,
    ),
}
"""The kinds a new runner starts with (the runner copies it)."""
