"""The editor's `export` job: a site's live elements through `cama_pipeline.export.export` (every format it
has, refined poses from the site's reconstruction by default), zipped into `export.zip`.

Where the reconstruction comes from: a site registered on a surface stage's raster folder
(`<workspace>/surface/<site_id>/bev`) has that workspace's SfM outputs; a site on any other raster folder, or one
whose workspace has no SfM poses, has none. A refined-pose export of it is refused at submission
(`check_export`, a 422 naming `poses`); a coarse one (the data set's logged poses) stays possible.

What an API caller reads (submission errors, the job's message) never holds a server path: paths the export
names are replaced by the request field they come from (`<dataset_root>`, `<workspace>`), and the server log
keeps the whole message.
"""

import logging
import os
import shutil
import zipfile
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Self

import numpy as np
from pydantic import AfterValidator, BaseModel, Field, model_validator
from sqlalchemy.orm import Session

from annotations.kerb_evidence import check_semantic
from annotations.lanelet2_format import MapProjection
from annotations.schema import AnnotationSet, Georeference
from app.backend.data_roots import data_folder_validator
from app.backend.jobs.kinds import lift_elements, read_elevation, site_annotations
from app.backend.jobs.runner import JobCancelled, JobContext, JobKind, JobResult
from app.backend.models import Site
from app.backend.schemas import STRICT
from cama_pipeline.bev import layer_path, read_layer
from cama_pipeline.data import DatasetError
from cama_pipeline.data.map_origins import NUSCENES_MAP_ORIGINS
from cama_pipeline.export import CamaMode, ExportFormat, ExportRequest, ExportResult, PoseChoice, export
from cama_pipeline.export.request import FORMATS_NEEDING_DATASET
from cama_pipeline.export.run import WRITERS, SiteOriginUnknown, site_map_origin
from cama_pipeline.progress import ProgressObserver, observed_progress
from cama_pipeline.workspace import SiteLocation, Workspace

logger = logging.getLogger(__name__)

EXPORT_ZIP = "export.zip"
EXPORT_FOLDER = "export"
"""The export's final name inside the job's folder (a folder format is this folder; a file format's file lies
in it), staged beside it as `.export.partial-<id>` by `cama_pipeline.export.staging`."""
PARTIAL_SUFFIX = ".partial"
SINGLE_FILE_NAMES: dict[ExportFormat, str] = {
    ExportFormat.maptr: "maptr.json",
    ExportFormat.lanelet2: "map.osm",
}
"""The file a single-file format writes, at the top of the archive."""
_STAGING_LEFTOVERS = (f".{EXPORT_FOLDER}.partial-*", f".{EXPORT_FOLDER}.old-*")
"""What `cama_pipeline.export.staging` leaves beside the export when the process dies mid-export."""
_SUMMARY_LIMIT = 1000
NO_WORKSPACE = "no-reconstruction"
"""The workspace a site without a reconstruction exports with (never created, so it has no sites and no
masks): a coarse export of it covers the data set's scenes instead of guessing a reconstruction from the data
set's default workspace."""

SceneName = Annotated[str, Field(min_length=1, max_length=256)]


class ExportParams(BaseModel):
    """Parameters of an `export` job (see `cama_pipeline.export.ExportRequest`)."""

    model_config = STRICT
    format: Annotated[ExportFormat, Field(strict=False)] = ExportFormat.cama
    """cama (CAMA's release layout), maptr (per-sample vectors), nuscenes-cama (a nuScenes root with the refined
    ego poses), lanelet2 (an OSM map)."""
    poses: Annotated[PoseChoice, Field(strict=False)] = PoseChoice.refined
    """refined (the site's reconstruction: SfM, WIGO corrected by SfM) or coarse (the data set's logged poses)."""
    mode: Annotated[CamaMode, Field(strict=False)] = CamaMode.clip
    """cama: clip (a 300 m map per scene) or site (a 600 m site map, cut per scene)."""
    with_clip_data: bool = False
    """cama: also write each scene's images, lane masks (CAMA's ids) and attribute.json."""
    origin_lat_lon: list[float] | None = Field(default=None, min_length=2, max_length=2)
    """lanelet2: the geographic origin [lat, lon] in degrees of the site's global frame. Without it (and without
    `origin_location`), the origin of the site's reconstruction's location when that is a nuScenes one; else the
    job fails saying so."""
    origin_location: str | None = Field(default=None, max_length=64)
    """lanelet2: a nuScenes location whose map origin to use instead of `origin_lat_lon`."""
    projection: Annotated[MapProjection | None, Field(strict=False)] = None
    """lanelet2: local (a tangent plane at the origin, as nuScenes' maps) or utm (the UTM grid there); default
    local for a nuScenes location's origin, utm for `origin_lat_lon`."""
    dataset_root: Annotated[str | None, AfterValidator(data_folder_validator)] = Field(
        default=None, max_length=4096
    )
    """The data set (nuScenes layout) the site was reconstructed from; required for cama, maptr and
    nuscenes-cama. It must lie inside the server's data roots; stored resolved."""
    scenes: list[SceneName] | None = Field(default=None, min_length=1, max_length=10_000)
    """Only these scenes (default: the site's scenes)."""

    @model_validator(mode="after")
    def _what_the_format_needs(self) -> Self:
        lanelet2 = (self.origin_lat_lon, self.origin_location, self.projection)
        if self.format is not ExportFormat.lanelet2 and any(value is not None for value in lanelet2):
            raise ValueError("origin_lat_lon, origin_location, projection: only for format 'lanelet2'")
        if self.format in FORMATS_NEEDING_DATASET and not self.dataset_root:
            raise ValueError(
                f"dataset_root: required for format {self.format.value!r} (its poses and samples)"
            )
        if self.origin_lat_lon is not None and self.origin_location is not None:
            raise ValueError("origin_lat_lon, origin_location: one or the other")
        if self.origin_location is not None and self.origin_location not in NUSCENES_MAP_ORIGINS:
            raise ValueError(f"origin_location: one of {list(NUSCENES_MAP_ORIGINS)}")
        if self.origin_lat_lon is not None:
            lat, lon = self.origin_lat_lon
            if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0):
                raise ValueError(
                    "origin_lat_lon: [lat, lon] in degrees, lat in [-90, 90], lon in [-180, 180]"
                )
        if self.with_clip_data and self.format is not ExportFormat.cama:
            raise ValueError("with_clip_data: only for format 'cama'")
        return self

    @property
    def needs_reconstruction(self) -> bool:
        """Whether the export writes poses taken from the site's reconstruction."""
        return self.poses is PoseChoice.refined and self.format in FORMATS_NEEDING_DATASET


def locate_reconstruction(raster_dir: Path) -> SiteLocation | None:
    """The workspace and reconstruction site of a site's raster folder, when it is a surface stage's output."""
    try:
        return Workspace.locate(raster_dir)
    except ValueError:
        return None


def reconstruction(raster_dir: Path, name: str) -> SiteLocation:
    """The site's reconstruction with its SfM poses; ValueError naming `poses` and why there is none (no path)."""
    location = locate_reconstruction(raster_dir)
    if location is None:
        raise ValueError(
            f"poses: site {name!r} has no reconstruction (its rasters are not a surface stage's output, "
            "<workspace>/surface/<site>/bev), so it has no refined poses; export with poses 'coarse' (the data "
            "set's logged poses) or register the site on its reconstruction's rasters"
        )
    if not location.workspace.sfm_poses(location.site_id).is_file():
        raise ValueError(
            f"poses: site {name!r} has no reconstruction: its workspace has no SfM poses for site "
            f"{location.site_id!r} (run `cama sfm`), so it has no refined poses; export with poses 'coarse'"
        )
    return location


def check_export(session: Session, site_id: int, params: ExportParams) -> None:
    """Refuse at submission what cannot run: a format this build has no writer for, a refined-pose export of
    a site without a reconstruction; ValueError starting with the field's name."""
    if params.format not in WRITERS:
        available = ", ".join(sorted(WRITERS))
        raise ValueError(
            f"format: {params.format.value!r} is not available in this build (available: {available})"
        )
    needs_site_origin = params.format is ExportFormat.lanelet2 and (
        params.origin_lat_lon is None and params.origin_location is None
    )
    if not (params.needs_reconstruction or needs_site_origin):
        return
    site = session.get(Site, site_id)
    if site is None:
        raise ValueError(f"site {site_id}: not found")
    if params.needs_reconstruction:
        reconstruction(Path(site.raster_dir), site.name)
    if needs_site_origin:
        check_site_origin(Path(site.raster_dir), site.name)


def check_site_origin(raster_dir: Path, name: str) -> None:
    """A lanelet2 export without an origin takes its site's location's (`ExportRequest.origin_lat_lon`); ValueError
    naming `origin_lat_lon` when the site's reconstruction gives none (`site_map_origin`)."""
    needed = f"origin_lat_lon: required for format 'lanelet2' (or origin_location: one of {list(NUSCENES_MAP_ORIGINS)})"
    location = locate_reconstruction(raster_dir)
    if location is None:
        raise ValueError(f"{needed}: site {name!r} has no reconstruction whose location would give it")
    try:
        site_map_origin(location.workspace, location.site_id, location.site_id, name)
    except SiteOriginUnknown as error:
        raise ValueError(f"{needed}: {error}") from None


def _elevation(raster_dir: Path, georef: Georeference, name: str) -> np.ndarray | None:
    """The site's elevation raster, or None (logged) when the raster folder has no usable one."""
    try:
        return read_elevation(raster_dir, georef)
    except (FileNotFoundError, ValueError) as error:
        logger.warning("site %s: exporting without elevation: %s", name, error)
        return None


def _semantic(raster_dir: Path, georef: Georeference, name: str) -> np.ndarray | None:
    """The site's semantic raster (Lanelet2's kerb evidence), or None (logged; boundaries stay assumed kerbs)."""
    try:
        return check_semantic(
            read_layer(raster_dir, "semantic"), georef, name=str(layer_path(raster_dir, "semantic"))
        )
    except (FileNotFoundError, ValueError) as error:
        logger.warning("site %s: exporting Lanelet2 without kerb evidence: %s", name, error)
        return None


@dataclass(frozen=True)
class ExportJob:
    """What one export job writes, and what its messages say."""

    request: ExportRequest
    name: str
    """The site's name."""
    lifted: str
    """How many elements carry heights from the site's elevation raster (for the message)."""
    hidden: dict[Path, str]
    """Server paths to keep out of messages, with the label that replaces each (`redact`)."""


def _lift(annotations: AnnotationSet, elevation: np.ndarray | None) -> tuple[AnnotationSet, str]:
    """The elements with their heights from the site's elevation raster (the editor stores 2D points), so that
    MapTR vectors and Lanelet2 `ele` carry the measured surface; unlifted where there is no raster."""
    total = len(annotations.elements)
    if elevation is None:
        return annotations, f"0 of {total} lifted (no elevation raster)"
    lifted = lift_elements(annotations, elevation)
    return lifted.annotations, f"{total - len(lifted.flagged)} of {total} lifted"


def export_job(context: JobContext, params: ExportParams) -> ExportJob:
    """The request of one job: the site's live elements lifted through its elevation raster, its reconstruction
    (refined poses: checked again, it may have gone since submission), the out path in the job's folder."""
    annotations, raster_dir, name = site_annotations(context)
    location = (
        reconstruction(raster_dir, name) if params.needs_reconstruction else locate_reconstruction(raster_dir)
    )
    elevation = _elevation(raster_dir, annotations.georeference, name)
    annotations, lifted = _lift(annotations, elevation)
    folder = context.workdir / EXPORT_FOLDER
    file_name = SINGLE_FILE_NAMES.get(params.format)
    dataset_root = Path(params.dataset_root) if params.dataset_root else None
    origin = params.origin_lat_lon
    lanelet2 = params.format is ExportFormat.lanelet2
    request = ExportRequest(
        annotations=annotations,
        out=folder / file_name if file_name else folder,
        format=params.format,
        dataset_root=dataset_root,
        workspace=location.workspace.root if location else context.workdir / NO_WORKSPACE,
        site_id=location.site_id if location else None,
        poses=params.poses,
        elevation=elevation if params.format is ExportFormat.cama else None,
        semantic=_semantic(raster_dir, annotations.georeference, name) if lanelet2 else None,
        scenes=tuple(params.scenes) if params.scenes else None,
        cama_mode=params.mode,
        with_clip_data=params.with_clip_data,
        origin_lat_lon=(origin[0], origin[1]) if origin else None,
        origin_location=params.origin_location,
        projection=params.projection,
    )
    hidden = {context.workdir: "<job>", raster_dir: "<rasters>"}
    if dataset_root is not None:
        hidden[dataset_root] = "<dataset_root>"
    if location is not None:
        hidden[location.workspace.root] = "<workspace>"
    return ExportJob(request, name, lifted, hidden)


def redact(text: str, hidden: Mapping[Path, str]) -> str:
    """`text` with each server path in `hidden` (as given and resolved; the longest first, so a path inside
    another is named by the inner one) replaced by its label."""
    names: dict[str, str] = {}
    for path, label in hidden.items():
        for form in (str(path), str(path.absolute()), str(path.resolve())):
            names.setdefault(form, label)
    for form in sorted(names, key=len, reverse=True):
        text = text.replace(form, names[form])
    return text


def _describe(value: object) -> str:
    """A summary value for the job's message: a count for a collection, `key value` pairs for a mapping."""
    if isinstance(value, Mapping):
        return "(" + ", ".join(f"{key} {_describe(item)}" for key, item in value.items()) + ")"
    if isinstance(value, list | tuple | set | frozenset):
        return str(len(value))
    return str(value)


def summary_message(result: ExportResult, job: ExportJob) -> str:
    """One line: what was exported, in which format, with which poses, and the writer's counts."""
    poses = [f"{result.poses.value} poses"] if result.format in FORMATS_NEEDING_DATASET else []
    parts = [result.format.value, *poses, f"{result.files} files", job.lifted]
    parts += [f"{key} {_describe(value)}" for key, value in result.summary.items()]
    message = f"exported {result.elements} elements of {job.name} ({', '.join(parts)})"
    message = redact(message, job.hidden)
    return message if len(message) <= _SUMMARY_LIMIT else message[: _SUMMARY_LIMIT - 3] + "..."


def failure_message(error: Exception, hidden: Mapping[Path, str]) -> str:
    """What a failed export tells the API caller: the error with server paths replaced (`redact`); a data set
    error names `dataset_root` and leaves out the folder listing the loader adds (the server log has it)."""
    if isinstance(error, DatasetError):
        detail = error.detail.split("; subfolders found", 1)[0]
        shown = DatasetError(detail, path=error.path, record=error.record, field=error.field)
        return redact(f"dataset_root: not a usable data set: {shown}", hidden)
    return redact(f"{type(error).__name__}: {error}", hidden)


EXPORT_PROGRESS = (0.1, 0.8)
"""The job's progress while the export writes: each of the export's bars (scenes, a scene's clip data, map
vectors) fills this span in turn, its text and counts in the job's message."""


def progress_observer(context: JobContext) -> ProgressObserver:
    """Each step of the export's progress bars as the job's progress and message; a cancel asked for meanwhile
    stops the export at that step (`JobContext.report` raises, the staging is removed)."""
    low, high = EXPORT_PROGRESS

    def observe(text: str, completed: float, total: float | None) -> None:
        fraction = min(1.0, completed / total) if total else 0.0
        counts = f"{completed:.0f}/{total:.0f}" if total else f"{completed:.0f}"
        context.report(low + (high - low) * fraction, f"{text} {counts}")

    return observe


class ExportFailed(Exception):
    """An export that could not be written; the message names what is wrong without server paths."""


def run_export(context: JobContext, params: ExportParams) -> JobResult:
    """Export the live elements through `cama_pipeline.export.export` into `<job>/export` (staged, renamed
    when complete) and zip it into `<job>/export.zip` (written atomically)."""
    clean_export(context.workdir)
    try:
        job = export_job(context, params)
    except ValueError as error:  # the reconstruction went away since submission
        raise ExportFailed(str(error)) from None
    count = len(job.request.annotations.elements)
    context.report(EXPORT_PROGRESS[0], f"exporting {count} elements ({params.format.value})", force=True)
    try:
        with observed_progress(progress_observer(context)):
            result = export(job.request)
    except JobCancelled:
        raise
    except Exception as error:
        logger.warning("export job %d of site %s failed: %s", context.job_id, job.name, error)
        raise ExportFailed(failure_message(error, job.hidden)) from None
    context.report(EXPORT_PROGRESS[1], "packing the archive", force=True)
    archive = zip_folder(context.workdir / EXPORT_FOLDER, context.workdir / EXPORT_ZIP, context)
    return JobResult(archive, summary_message(result, job))


def archived_files(folder: Path) -> list[Path]:
    """The regular files under `folder`, sorted; symbolic links are not followed nor archived: the
    nuScenes-CAMAv2 root links the source data set's samples/, sweeps/, ... so that its image paths resolve, and
    the archive carries what the export wrote (its version folder), never what a link reaches on the server."""
    files: list[Path] = []
    for root, _folders, names in os.walk(folder, followlinks=False):
        files += [Path(root, name) for name in names if not Path(root, name).is_symlink()]
    return sorted(path for path in files if path.is_file())


def zip_folder(folder: Path, archive: Path, context: JobContext) -> Path:
    """Zip every regular file under `folder` (names relative to it; `archived_files`) into `archive`, written
    atomically."""
    files = archived_files(folder)
    partial = archive.with_name(archive.name + PARTIAL_SUFFIX)
    with zipfile.ZipFile(partial, "w", compression=zipfile.ZIP_DEFLATED) as bundle:
        for index, path in enumerate(files):
            bundle.write(path, path.relative_to(folder).as_posix())
            context.report(0.8 + 0.19 * (index + 1) / len(files))
    os.replace(partial, archive)
    return archive


def _remove(path: Path) -> None:
    """Remove a folder or a file."""
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    else:
        path.unlink(missing_ok=True)


def clean_export(workdir: Path) -> None:
    """Remove an export's unzipped folder, its staging leftovers and a half-written archive; the finished
    `export.zip` stays."""
    _remove(workdir / EXPORT_FOLDER)
    for pattern in _STAGING_LEFTOVERS:
        for leftover in workdir.glob(pattern):
            _remove(leftover)
    (workdir / (EXPORT_ZIP + PARTIAL_SUFFIX)).unlink(missing_ok=True)


EXPORT_JOB_KINDS: dict[str, JobKind] = {
    "export": JobKind(
        ExportParams,
        run_export,
        "Export the live elements: cama, maptr, nuscenes-cama (with the data set) or lanelet2 (with an "
        "origin, or at its nuScenes location's); refined poses from the site's reconstruction, or coarse ones when asked for.",
        cleanup=clean_export,
        check=check_export,
    ),
}
"""The export kind (the app composes it with `kinds.JOB_KINDS`)."""
