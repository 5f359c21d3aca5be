"""`cama export` / `cama import`: the command line over `cama_pipeline.export` (CAMA's release layout, MapTR
vectors, a nuScenes-CAMAv2 root, Lanelet2) and the importers of CAMA labels and MapTR vectors.

Export writes refined ego poses by default (`cama_pipeline.refined_poses`: SfM poses, WIGO corrected between
SfM keyframes); the logged poses only with `--poses coarse`.

The JSON Schema files in `annotations/schemas/` are generated from the file models: `python -m
cama_studio.export_command` rewrites them (a test checks the committed files equal the generated ones).
"""

import json
import logging
from pathlib import Path
from typing import Annotated, Any

import cv2
import numpy as np
import typer
from pydantic import BaseModel

from annotations import cama_format
from annotations.cama_cut import DEFAULT_OBSERVED_RADIUS_M
from annotations.cama_format import DEFAULT_RELEASE_RESOLUTION_M, CamaMapLabels, import_cama
from annotations.kerb_evidence import check_semantic
from annotations.lanelet2_format import MapProjection
from annotations.maptr_format import MaptrFile, import_maptr
from annotations.schema import AnnotationSet, Georeference
from cama_pipeline.bev import is_raster_folder, read_bev
from cama_pipeline.cli_options import MasksOpt
from cama_pipeline.console import bad_input
from cama_pipeline.data import DatasetError
from cama_pipeline.data.map_origins import NUSCENES_MAP_ORIGINS
from cama_pipeline.data.masks import parse_mask_choice
from cama_pipeline.export import CamaMode, ExportFormat, ExportRequest, PoseChoice, export
from cama_pipeline.export.poses import export_site_id
from cama_pipeline.io import WorkspaceError, atomic_write_bytes
from cama_pipeline.workspace import Workspace

logger = logging.getLogger(__name__)

SCHEMA_DIR = Path(cama_format.__file__).parent / "schemas"
SCHEMA_MODELS: dict[str, type[BaseModel]] = {
    "cama_map_labels.schema.json": CamaMapLabels,
    "maptr_vectors.schema.json": MaptrFile,
}


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


def load_semantic(path: Path, georef: Georeference) -> np.ndarray:
    """A semantic BEV raster from a .npy file, an image (a raster folder's semantic.png) or a raster folder (its
    semantic layer, its georeference the annotation set's); ValueError naming `path` when unreadable or not of
    the set's georeference."""
    try:
        if path.is_dir():
            rasters = read_bev(path, ["semantic"])
            if rasters.georeference != georef.as_raster():
                raise ValueError("its georeference.json is not the annotation set's georeference")
            semantic = rasters.require("semantic")
        elif path.suffix == ".npy":
            semantic = np.asarray(np.load(path, allow_pickle=False))
        else:
            image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
            if image is None:
                raise ValueError("not a readable .npy or image file")
            semantic = image
        return check_semantic(semantic, georef, name="raster")
    except (OSError, ValueError) as error:
        raise ValueError(f"{path}: cannot use as the semantic raster: {error}") from error


def default_semantic_folder(
    workspace: Path | None, dataset: Path | None, annotations: AnnotationSet, site_id: str | None
) -> Path | None:
    """The surface raster folder of the site the export takes its poses from (`export_site_id`: `--site-id`, else
    the annotation set's site, else the workspace's only site), in the export's workspace (`--workspace`, else the
    data set's); None when the workspace names no such site or the site has no raster, so the kerbs and the poses
    always come from one site."""
    if workspace is not None:
        space = Workspace(workspace)
    elif dataset is not None:
        space = Workspace.for_dataset(dataset)
    else:
        return None
    try:
        site = export_site_id(space, annotations.site_id, site_id)
    except (FileNotFoundError, ValueError):
        return None
    bev = space.surface_bev(site)
    return bev if is_raster_folder(bev) else None


def _semantic(
    path: Path | None, format: ExportFormat, annotations: AnnotationSet, default: Path | None
) -> tuple[np.ndarray | None, str]:
    """The semantic raster for the export (the given file, else lanelet2's default) and where it came from."""
    if path is not None:
        return load_semantic(path, annotations.georeference), str(path)
    if format is not ExportFormat.lanelet2 or default is None:
        return None, "none"
    try:
        return load_semantic(default, annotations.georeference), str(default)
    except (FileNotFoundError, ValueError) as error:
        logger.warning("exporting without kerb evidence: %s", error)
        return None, f"none ({error})"


def parse_origin(text: str | None) -> tuple[tuple[float, float] | None, str | None]:
    """`--origin`: `LAT,LON` in degrees, or a nuScenes location's name; (lat_lon, location), one of them set,
    or (None, None) when not given. ValueError naming the option when it is neither."""
    if text is None:
        return None, None
    if text.strip() in NUSCENES_MAP_ORIGINS:
        return None, text.strip()
    try:
        lat, lon = (float(part) for part in text.split(","))
    except ValueError:
        raise ValueError(
            f"--origin {text!r}: expected LAT,LON in degrees (e.g. 1.2990,103.7880) or a nuScenes location "
            f"({', '.join(NUSCENES_MAP_ORIGINS)})"
        ) from None
    return (lat, lon), None


def export_command(
    annotations_json: Annotated[Path, typer.Argument(help="Annotation set JSON (AnnotationSet).")],
    out: Annotated[
        Path,
        typer.Argument(help="cama, nuscenes-cama: output folder; maptr: JSON file; lanelet2: .osm file."),
    ],
    format: Annotated[ExportFormat, typer.Option("--format", help="The export format.")] = ExportFormat.cama,
    dataset: Annotated[
        Path | None,
        typer.Option(help="Data set root (nuScenes layout): needed by cama, maptr and nuscenes-cama."),
    ] = None,
    elevation: Annotated[Path | None, typer.Option(help="Elevation raster .npy (H, W) for cama.")] = None,
    semantic: Annotated[
        Path | None,
        typer.Option(
            help="lanelet2: semantic BEV raster (.npy, semantic.png or a raster folder) in the set's "
            "georeference; a boundary along curb becomes curbstone, one at a road edge without curb road_border, "
            "one too little seen an assumed curbstone. Default: the workspace's surface/<site>/bev when there "
            "is one (--workspace, or the data set's; the --site-id's, the set's or the only site)."
        ),
    ] = None,
    name: Annotated[str | None, typer.Option(help="cama: the site's name (default: site id).")] = None,
    scene: Annotated[
        list[str] | None,
        typer.Option(help="Only this scene (repeatable; default: the site's scenes)."),
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
    mode: Annotated[
        CamaMode,
        typer.Option(help="cama: clip (a 300 m map per scene) or site (a 600 m site map, cut per scene)."),
    ] = CamaMode.clip,
    with_clip_data: Annotated[
        bool, typer.Option(help="cama: also write images, lane masks (CAMA's ids) and attribute.json.")
    ] = False,
    observed_radius_m: Annotated[
        float,
        typer.Option(
            help="cama: a scene's labels are the elements within this many metres of its cameras' paths."
        ),
    ] = DEFAULT_OBSERVED_RADIUS_M,
    masks: MasksOpt = "auto",
    origin: Annotated[
        str | None,
        typer.Option(
            help="lanelet2: the geographic origin of the site's global frame: LAT,LON, or a nuScenes location "
            f"({', '.join(NUSCENES_MAP_ORIGINS)}). Default: the origin of the site's location when it is a "
            "nuScenes one (the workspace's sites index)."
        ),
    ] = None,
    projection: Annotated[
        MapProjection | None,
        typer.Option(
            help="lanelet2: local (a tangent plane at the origin, as nuScenes' maps) or utm (the UTM grid at "
            "the origin). Default: local for a nuScenes location's origin, utm for LAT,LON."
        ),
    ] = None,
    overwrite: Annotated[bool, typer.Option(help="Replace an existing export at OUT.")] = False,
) -> None:
    """Export an annotation set (refined poses by default); the export appears at OUT only when complete."""
    try:
        origin_lat_lon, origin_location = parse_origin(origin)
        annotation_set = AnnotationSet.read_json(annotations_json)
        default = default_semantic_folder(workspace, dataset, annotation_set, site_id)
        semantic_raster, semantic_source = _semantic(semantic, format, annotation_set, default)
        request = ExportRequest(
            annotations=annotation_set,
            site_name=name,
            out=out,
            format=format,
            dataset_root=dataset,
            workspace=workspace,
            site_id=site_id,
            poses=poses,
            elevation=_load_elevation(elevation),
            semantic=semantic_raster,
            scenes=tuple(scene) if scene else None,
            cama_mode=mode,
            observed_radius_m=observed_radius_m,
            with_clip_data=with_clip_data,
            masks=parse_mask_choice(masks),
            origin_lat_lon=origin_lat_lon,
            origin_location=origin_location,
            projection=projection,
            overwrite=overwrite,
            show_progress=True,
        )
        result = export(request)
    except (ValueError, FileNotFoundError, FileExistsError, DatasetError, WorkspaceError) as error:
        raise bad_input(error) from error
    typer.echo(
        f"exported {result.elements} elements ({format.value}, {poses.value} poses, {result.files} files) "
        f"to {result.path}"
    )
    if format is ExportFormat.lanelet2:
        kerbs = result.summary.get("kerbs", {})
        typer.echo(f"boundaries by kerb evidence {kerbs} (semantic raster: {semantic_source})")
        typer.echo(
            f"origin {result.summary.get('origin_lat_lon')} ({result.summary.get('origin_source')}), "
            f"projection {result.summary.get('projection')}"
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
