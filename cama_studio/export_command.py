"""`cama export` / `cama import`: annotation sets to and from the CAMA release layout and MapTR vectors JSON.

Export writes refined ego poses by default (`cama_pipeline.refined_poses`: SfM poses, WIGO corrected between
SfM keyframes), so it composes stage outputs and lives here, above the stages; the logged poses only with
`--poses coarse`.

The JSON Schema files in `annotations/schemas/` are generated from the file models: `python -m
cama_studio.export_command` rewrites them (a test checks the committed files equal the generated ones).
"""

import json
import logging
from enum import StrEnum
from pathlib import Path
from typing import Annotated, Any

import numpy as np
import typer
from pydantic import BaseModel

from annotations import cama_format
from annotations.cama_format import DEFAULT_RELEASE_RESOLUTION_M, CamaMapLabels, export_cama, import_cama
from annotations.maptr_format import MaptrFile, export_maptr, import_maptr
from annotations.poses import PoseLookup, coarse_pose
from annotations.schema import AnnotationSet, Georeference
from cama_pipeline.console import bad_input
from cama_pipeline.data import Dataset, DatasetError, load_dataset
from cama_pipeline.io import WorkspaceError, atomic_write_bytes
from cama_pipeline.refined_poses import refined_pose_lookup, refined_poses
from cama_pipeline.site.io import read_site_ids
from cama_pipeline.workspace import Workspace

logger = logging.getLogger(__name__)

SCHEMA_DIR = Path(cama_format.__file__).parent / "schemas"
SCHEMA_MODELS: dict[str, type[BaseModel]] = {
    "cama_map_labels.schema.json": CamaMapLabels,
    "maptr_vectors.schema.json": MaptrFile,
}


class ExportFormat(StrEnum):
    """Which file format."""

    cama = "cama"
    maptr = "maptr"


class PoseChoice(StrEnum):
    """Which ego poses the export writes."""

    refined = "refined"
    coarse = "coarse"


def export_site_id(workspace: Workspace, annotation_site_id: str, site_id: str | None) -> str:
    """The site whose reconstruction gives the poses: `site_id`, else the annotation set's site when the
    workspace has it, else the workspace's only site; ValueError / FileNotFoundError saying what to pass."""
    if site_id is not None:
        return site_id
    index = workspace.sites_index()
    if not index.is_file():
        raise FileNotFoundError(f"{index}: missing; run `cama sites` .. `cama sfm`, or pass --poses coarse")
    sites = read_site_ids(index)
    if annotation_site_id in sites:
        return annotation_site_id
    if len(sites) == 1:
        return sites[0]
    raise ValueError(
        f"{index}: sites {sites}; pass --site-id (the annotation set's is {annotation_site_id!r})"
    )


def pose_lookup(
    choice: PoseChoice, data: Dataset, workspace: Workspace, annotation_site_id: str, site_id: str | None
) -> tuple[PoseLookup, list[str] | None]:
    """The export's pose lookup and, for refined poses, the site's scenes (the odometry's default scenes)."""
    if choice is PoseChoice.coarse:
        return coarse_pose, None
    site = export_site_id(workspace, annotation_site_id, site_id)
    try:
        poses = refined_poses(data, workspace, site)
    except FileNotFoundError as error:
        raise FileNotFoundError(
            f"refined poses need the SfM outputs: {error}; run `cama sfm` first, or pass --poses coarse"
        ) from error
    scenes = sorted(
        {scene.name for scene in data.scenes if any(im.token in poses for im in scene.all_images())}
    )
    return refined_pose_lookup(poses), scenes


def schema_text(model: type[BaseModel]) -> str:
    """The JSON Schema of a file model, as committed (sorted keys, 2-space indent, trailing newline)."""
    return json.dumps(model.model_json_schema(), indent=2, sort_keys=True) + "\n"


def write_schemas(folder: Path = SCHEMA_DIR) -> list[Path]:
    """(Re)write every schema file from its model."""
    paths = []
    for name, model in SCHEMA_MODELS.items():
        atomic_write_bytes(folder / name, schema_text(model).encode("utf-8"))
        paths.append(folder / name)
    return paths


def _load_elevation(path: Path | None) -> np.ndarray | None:
    """The elevation raster from a .npy file, or None."""
    if path is None:
        return None
    try:
        return np.asarray(np.load(path, allow_pickle=False))
    except (OSError, ValueError) as error:
        raise ValueError(f"{path}: cannot read elevation raster: {error}") from error


def export_command(
    annotations_json: Annotated[Path, typer.Argument(help="Annotation set JSON (AnnotationSet).")],
    out: Annotated[Path, typer.Argument(help="cama: output folder; maptr: output JSON file.")],
    format: Annotated[ExportFormat, typer.Option("--format", help="cama or maptr.")] = ExportFormat.cama,
    dataset: Annotated[
        Path | None, typer.Option(help="Data set root (nuScenes layout): needed for maptr and cama odometry.")
    ] = None,
    elevation: Annotated[Path | None, typer.Option(help="Elevation raster .npy (H, W) for cama.")] = None,
    name: Annotated[
        str | None, typer.Option(help="cama: scene or site folder name (default: site id).")
    ] = None,
    scene: Annotated[
        list[str] | None,
        typer.Option(help="cama odometry: only this scene (repeatable; default: the site's, refined poses)."),
    ] = None,
    poses: Annotated[
        PoseChoice,
        typer.Option(
            help="refined (SfM, WIGO corrected by SfM) or coarse (the data set's logged ego poses)."
        ),
    ] = PoseChoice.refined,
    workspace: Annotated[
        Path | None, typer.Option(help="Workspace with the SfM outputs (default: the data set's).")
    ] = None,
    site_id: Annotated[
        str | None,
        typer.Option(help="Site whose SfM gives the poses (default: the annotation set's, or the only one)."),
    ] = None,
) -> None:
    """Export an annotation set to the CAMA release layout or to MapTR vectors JSON (refined poses by default)."""
    try:
        annotation_set = AnnotationSet.read_json(annotations_json)
        data = load_dataset(dataset) if dataset is not None else None
        lookup: PoseLookup | None = None
        if data is not None and dataset is not None:
            space = Workspace.resolve(workspace, dataset)
            lookup, site_scenes = pose_lookup(poses, data, space, annotation_set.site_id, site_id)
            scene = scene or site_scenes
        if format is ExportFormat.maptr:
            if data is None or lookup is None:
                raise ValueError("--format maptr needs --dataset ROOT (sample tokens and ego poses)")
            written = export_maptr(annotation_set, data, out, poses=lookup)
        else:
            raster = _load_elevation(elevation)
            written = export_cama(
                annotation_set, out, name=name, elevation=raster, dataset=data, poses=lookup, scenes=scene
            )
    except (ValueError, FileNotFoundError, DatasetError, WorkspaceError) as error:
        raise bad_input(error) from error
    typer.echo(
        f"exported {len(annotation_set.elements)} elements ({format.value}, {poses.value} poses) to {written}"
    )


def import_command(
    path: Annotated[Path, typer.Argument(help="cama: scene/site folder (holds maps/); maptr: vectors JSON.")],
    out: Annotated[Path, typer.Option("--out", help="Annotation set JSON to write.")],
    format: Annotated[ExportFormat, typer.Option("--format", help="cama or maptr.")] = ExportFormat.cama,
    site_id: Annotated[
        str | None, typer.Option(help="Site id (default: the one stored in the files).")
    ] = None,
    stop_line_as_divider: Annotated[
        bool, typer.Option(help="cama: import Stop_Line as divider (skipped by default).")
    ] = False,
    georeference: Annotated[
        Path | None, typer.Option(help="maptr: georeference JSON when the file has none.")
    ] = None,
    resolution_m: Annotated[
        float, typer.Option(help="cama: metres per pixel of a plain release folder (no georeference.json).")
    ] = DEFAULT_RELEASE_RESOLUTION_M,
) -> None:
    """Import CAMA labels or MapTR vectors into an annotation set JSON, for review in the editor."""
    try:
        if format is ExportFormat.maptr:
            georef = _read_georeference(georeference)
            annotations = import_maptr(path, site_id=site_id, georeference=georef)
        else:
            annotations = import_cama(
                path, site_id=site_id, stop_line_as_divider=stop_line_as_divider, resolution_m=resolution_m
            )
        annotations.write_json(out)
    except (ValueError, FileNotFoundError) as error:
        raise bad_input(error) from error
    typer.echo(f"imported {len(annotations.elements)} elements ({format.value}) to {out}")


def _read_georeference(path: Path | None) -> Georeference | None:
    """A full Georeference JSON (with site_origin_xy), or None."""
    if path is None:
        return None
    try:
        obj: Any = json.loads(path.read_text(encoding="utf-8"))
        return Georeference.model_validate(obj.get("georeference", obj) if isinstance(obj, dict) else obj)
    except (OSError, ValueError) as error:
        raise ValueError(f"{path}: invalid georeference: {error}") from error


if __name__ == "__main__":
    for written in write_schemas():
        print(written)  # noqa: T201
