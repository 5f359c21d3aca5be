"""`export`: resolve what the request's format needs, write it staged, rename it into place."""

import logging
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from annotations.cama_clip_data import write_clip_data
from annotations.cama_release import export_cama_release
from annotations.kerb_evidence import kerb_evidence
from annotations.lanelet2_format import MapProjection, export_lanelet2
from annotations.maptr_format import build_maptr, write_maptr
from annotations.nuscenes_cama_format import export_nuscenes_cama
from cama_pipeline.data import Dataset, load_dataset
from cama_pipeline.data.map_origins import NUSCENES_MAP_ORIGINS, location_origin
from cama_pipeline.data.masks import mask_roots
from cama_pipeline.export.poses import ExportPoses, export_poses, export_site_id
from cama_pipeline.export.request import FORMATS_NEEDING_DATASET, ExportFormat, ExportRequest, ExportResult
from cama_pipeline.export.staging import staged_output
from cama_pipeline.site.io import read_site_location, read_site_scenes
from cama_pipeline.workspace import Workspace

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class ExportInputs:
    """What a format writer gets: the request and, for formats that need them, the data set and the poses."""

    request: ExportRequest
    dataset: Dataset | None
    poses: ExportPoses | None
    workspace: Workspace | None

    def need_dataset(self) -> tuple[Dataset, ExportPoses]:
        """The data set and poses (the request's validation guarantees them for the formats that call this)."""
        if self.dataset is None or self.poses is None:
            raise ValueError(f"--format {self.request.format.value} needs --dataset ROOT")
        return self.dataset, self.poses


Writer = Callable[[ExportInputs, Path], dict[str, object]]
"""A format writer: fills the staging path (a folder or a file) and returns its counts for the summary."""


def _write_cama(inputs: ExportInputs, staging: Path) -> dict[str, object]:
    data, poses = inputs.need_dataset()
    request = inputs.request
    result = export_cama_release(
        request.annotations,
        staging,
        dataset=data,
        poses=poses.lookup,
        scenes=list(request.scenes or poses.scenes),
        site_name=request.site_name or poses.site_id or request.annotations.site_id,
        mode=request.cama_mode.value,
        elevation=request.elevation,
        observed_radius_m=request.observed_radius_m,
        show_progress=request.show_progress,
    )
    summary: dict[str, object] = {
        "mode": result.mode,
        "scenes": {scene.scene: scene.instances for scene in result.scenes},
        "elevation": result.elevation_source,
    }
    if request.with_clip_data:
        summary["clip_data"] = _write_clip_data(inputs, [(s.scene, s.folder) for s in result.scenes])
    return summary


def _write_clip_data(inputs: ExportInputs, scenes: list[tuple[str, Path]]) -> dict[str, object]:
    """Each scene's images, lane masks (CAMA's ids) and attribute.json; the masks from the request's choice."""
    data, _poses = inputs.need_dataset()
    request = inputs.request
    roots = mask_roots(request.masks, data.root, inputs.workspace)
    frames = masks = 0
    missing: list[str] = []
    for scene, folder in scenes:
        clip = write_clip_data(folder, data, scene, lane_masks=roots, show_progress=request.show_progress)
        frames, masks = frames + clip.frames, masks + clip.masks_written
        missing.extend(item.image for item in clip.missing_masks)
    if missing:
        logger.warning(
            "clip data: %d synchronised images have no lane instance mask (CAMA's metric needs one per image), "
            "e.g. %s; run `cama segment` or choose --masks",
            len(missing),
            missing[0],
        )
    return {"frames": frames, "masks": masks, "missing_masks": len(missing)}


def _write_maptr(inputs: ExportInputs, staging: Path) -> dict[str, object]:
    data, poses = inputs.need_dataset()
    scenes = inputs.request.scenes or poses.scenes
    model = build_maptr(inputs.request.annotations, data, poses=poses.lookup, scenes=scenes)
    write_maptr(model, staging)
    sources = Counter(sample.pose_source for sample in model.samples)
    return {"scenes": list(scenes), "pose_sources": dict(sources)}


@dataclass(frozen=True)
class MapPlacement:
    """Where a lanelet2 export puts the site's global frame on the Earth, and what said so."""

    origin_lat_lon: tuple[float, float]
    projection: MapProjection
    source: str
    """`--origin`, `--origin LOCATION` or the site's location (its id and name)."""


def site_location(workspace: Workspace, annotation_site_id: str, site_id: str | None) -> tuple[str, str]:
    """The site the export's poses would come from (`export_site_id`) and its `log.location` from the sites
    index; FileNotFoundError / ValueError as `export_site_id`."""
    site = export_site_id(workspace, annotation_site_id, site_id)
    return site, read_site_location(workspace.sites_index(), site)


class SiteOriginUnknown(ValueError):
    """No map origin follows from a site's reconstruction; the message says why, to follow what to pass instead."""


def site_map_origin(
    workspace: Workspace, annotation_site_id: str, site_id: str | None, name: str | None = None
) -> tuple[tuple[float, float], str]:
    """The map origin of the `log.location` of the site whose poses an export would take (`site_location`) and
    where it lies ("site S at LOCATION"); SiteOriginUnknown when the workspace has no reconstruction, its sites do
    not give the site's location, or that location's origin is not known, naming the site as `name` (None: by
    the site id asked for or found). One rule for the CLI's and the backend's lanelet2 exports without an origin."""
    asked = name or site_id or annotation_site_id
    if not workspace.sites_index().is_file():
        raise SiteOriginUnknown(
            f"site {asked!r} has no reconstruction whose location would give it ({workspace.sites_index()} is missing)"
        )
    try:
        site, location = site_location(workspace, annotation_site_id, site_id)
    except (FileNotFoundError, ValueError) as error:
        raise SiteOriginUnknown(f"site {asked!r}: the site's location is unknown: {error}") from error
    origin = location_origin(location)
    if origin is None:
        raise SiteOriginUnknown(f"site {name or site!r} lies at {location!r}, whose map origin is not known")
    return origin, f"site {site} at {location}"


def map_placement(request: ExportRequest) -> MapPlacement:
    """The request's origin and projection (`ExportRequest.origin_lat_lon`'s defaults); ValueError naming what to
    pass when neither the request nor the site's location gives an origin."""
    if request.origin_lat_lon is not None:
        return MapPlacement(request.origin_lat_lon, request.projection or MapProjection.utm, "--origin")
    if request.origin_location is not None:
        origin = NUSCENES_MAP_ORIGINS[request.origin_location]
        return MapPlacement(
            origin, request.projection or MapProjection.local, f"--origin {request.origin_location}"
        )
    needed = (
        f"--format lanelet2 needs --origin LAT,LON or a nuScenes location ({', '.join(NUSCENES_MAP_ORIGINS)})"
    )
    if request.workspace is not None:
        workspace = Workspace(request.workspace)
    elif request.dataset_root is not None:
        workspace = Workspace.for_dataset(request.dataset_root)
    else:
        raise ValueError(f"{needed}, or the --dataset / --workspace of the site's reconstruction")
    try:
        origin, source = site_map_origin(workspace, request.annotations.site_id, request.site_id)
    except SiteOriginUnknown as error:
        raise ValueError(f"{needed}; {error}") from error
    return MapPlacement(origin, request.projection or MapProjection.local, source)


def _write_lanelet2(inputs: ExportInputs, staging: Path) -> dict[str, object]:
    request = inputs.request
    placement = map_placement(request)
    kerbs = (
        None if request.semantic is None else kerb_evidence(request.annotations, request.semantic).verdicts
    )
    result = export_lanelet2(
        request.annotations,
        staging,
        origin_lat_lon=placement.origin_lat_lon,
        projection=placement.projection,
        kerbs=kerbs,
    )
    return {
        "tags": result.counts,
        "kerbs": result.kerbs,
        "nodes": result.nodes,
        "unlifted": len(result.unlifted),
        "origin_lat_lon": list(placement.origin_lat_lon),
        "projection": placement.projection.value,
        "origin_source": placement.source,
    }


def _write_nuscenes_cama(inputs: ExportInputs, staging: Path) -> dict[str, object]:
    data, poses = inputs.need_dataset()
    scenes = inputs.request.scenes or poses.scenes
    result = export_nuscenes_cama(
        inputs.request.annotations,
        data.root,
        data,
        staging,
        poses=poses.lookup,
        scenes=scenes,
        show_progress=inputs.request.show_progress,
    )
    return {
        "version": result.version,
        "scenes": list(scenes),
        "pose_sources": result.counts,
        "samples": result.samples,
    }


WRITERS: dict[ExportFormat, Writer] = {
    ExportFormat.cama: _write_cama,
    ExportFormat.maptr: _write_maptr,
    ExportFormat.lanelet2: _write_lanelet2,
    ExportFormat.nuscenes_cama: _write_nuscenes_cama,
}
"""One writer per format."""


def _scenes_to_load(workspace: Workspace) -> list[str] | None:
    """The scenes of the workspace's sites (a large data set is then read by scene, not whole: nuscenes-cama
    keeps the logged poses of the other scenes' records), or None for every scene when it has no sites."""
    if not workspace.sites_index().is_file():
        return None
    return read_site_scenes(workspace.sites_index())


def export_inputs(request: ExportRequest) -> ExportInputs:
    """Load the data set and the poses the request's format needs (errors name the missing input)."""
    if request.dataset_root is None or request.format not in FORMATS_NEEDING_DATASET:
        return ExportInputs(request, None, None, None)
    dataset_root = Path(request.dataset_root)
    workspace = Workspace.resolve(request.workspace, dataset_root)
    data = load_dataset(dataset_root, scenes=_scenes_to_load(workspace))
    poses = export_poses(request.poses, data, workspace, request.annotations.site_id, request.site_id)
    if request.scenes is not None:
        unknown = sorted(set(request.scenes) - set(poses.scenes))
        if unknown:
            raise ValueError(f"--scene {unknown}: not among the exported scenes {list(poses.scenes)}")
    return ExportInputs(request, data, poses, workspace)


def export(request: ExportRequest) -> ExportResult:
    """Write the export of `request` at `request.out` atomically; ValueError / FileNotFoundError /
    FileExistsError naming what is wrong, with nothing left behind."""
    writer = WRITERS.get(request.format)
    if writer is None:
        raise ValueError(f"--format {request.format.value}: not available in this build")
    inputs = export_inputs(request)
    with staged_output(request.out, overwrite=request.overwrite) as staging:
        summary = writer(inputs, staging)
    out = Path(request.out).absolute()
    files = sum(1 for path in out.rglob("*") if path.is_file()) if out.is_dir() else 1
    logger.info("exported %d elements (%s) to %s", len(request.annotations.elements), request.format, out)
    return ExportResult(out, request.format, request.poses, len(request.annotations.elements), files, summary)
