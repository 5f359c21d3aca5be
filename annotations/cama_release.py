"""CAMA's public release layout (nuScenes-CAMAv2), written exactly as CAMA's tools read it, plus our sidecars.

    <out>/all_clips/<scene>/maps/map_labels.json         the scene's labels (`annotations.cama_labels`, `cama_cut`)
    <out>/all_clips/<scene>/maps/vision_road_mlp_ft.npy  float32 cells x cells elevation [v, u], no NaN
    <out>/all_clips/<scene>/odometry/<scmv|mcmv>_camera_<cam>.txt   TUM rows (`annotations.cama_odometry`)
    site mode only:
    <out>/site2clip/<site>_map_labels.json, <out>/site2clip/<site>_vision_road_mlp_ft.npy   the site map
    <out>/site2clip.json                                 {site: [scene, ...]}
Our extensions, ignored by CAMA's tools: `maps/georeference.json` and `maps/elevation_filled.png` per scene,
`site2clip/<site>_georeference.json` and `<site>_elevation_filled.png` (`annotations.cama_sidecar`), and
`odometry/pose_sources.json`.

Clip mode (`scmv`): each scene has its own 300 m map centred on its cameras' mean position (`cama_frame`). Site
mode (`mcmv`): one 600 m map centred on the mean position of every scene's cameras; each scene folder holds its
cut of the site's labels in that frame, and its elevation file is a hard link to the site's (a copy where the file
system has no hard links), as CAMA's own site2clip.py links them. A scene's labels are the elements within its
observed range (`cama_cut`); the site map holds every element within the map square. Only one elevation map is
in memory at a time (a 6000 x 6000 float32 is 144 MB).
"""

import json
import logging
import os
import shutil
import tempfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import shapely.affinity

from annotations.cama_cut import DEFAULT_OBSERVED_RADIUS_M, Piece, cut_elements, observed_range
from annotations.cama_elevation import (
    ELEVATION_NPY,
    FILLED_PNG,
    ReleaseElevation,
    constant_elevation,
    release_elevation,
)
from annotations.cama_frame import CAMA_MODES, MAP_SIDE_M, ODOMETRY_PREFIX, CamaMode, ReleaseFrame
from annotations.cama_labels import MAP_LABELS, cama_instance, validated_instances
from annotations.cama_odometry import CameraPose, scene_camera_poses, write_odometry
from annotations.cama_sidecar import CamaReleaseGeoreference, ElevationSource
from annotations.geometry import densify
from annotations.lift import DEFAULT_MAX_SPACING_M
from annotations.poses import PoseLookup
from annotations.schema import AnnotationSet
from cama_pipeline.data import Dataset, Scene
from cama_pipeline.io import atomic_write_bytes
from cama_pipeline.progress import StageProgress

logger = logging.getLogger(__name__)

ALL_CLIPS = "all_clips"
SITE2CLIP = "site2clip"
SITE2CLIP_JSON = "site2clip.json"
SCENE_SIDECAR = Path("maps/georeference.json")
SCENE_ELEVATION = Path("maps") / ELEVATION_NPY
SCENE_FILLED = Path("maps") / FILLED_PNG
ODOMETRY_DIR = "odometry"
SITE_LABELS_SUFFIX = "_map_labels.json"
SITE_ELEVATION_SUFFIX = f"_{ELEVATION_NPY}"
SITE_SIDECAR_SUFFIX = "_georeference.json"
SITE_FILLED_SUFFIX = f"_{FILLED_PNG}"
LABEL_SPACING_M = DEFAULT_MAX_SPACING_M
"""Label polylines are written with at most this spacing (the lift's): a reader that takes z from the elevation raster
at each label point (CAMA's code does) then follows the road surface between our vertices instead of cutting a
straight 3D chord (on the default site, exported proposals scored 3.92 px with the bare vertices and 3.14 px
densified, under the cama protocol, against 3.02 px before export: bench/export.py)."""


@dataclass(frozen=True)
class CamaSceneWritten:
    """One scene folder of the export."""

    scene: str
    folder: Path
    instances: int
    """Instances in its map_labels.json (pieces of cut elements count one each)."""
    odometry_rows: int
    filled_cells: int
    """Cells of its elevation map filled rather than observed (site mode: the site map's)."""


@dataclass(frozen=True)
class CamaReleaseResult:
    """What `export_cama_release` wrote."""

    out: Path
    mode: CamaMode
    site_name: str
    scenes: tuple[CamaSceneWritten, ...]
    site_files: tuple[Path, ...] = field(default=())
    """Site mode: the site2clip files and site2clip.json; clip mode: none."""
    site_instances: int = 0
    """Site mode: instances of the site map."""
    elevation_source: ElevationSource = "raster"


@dataclass(frozen=True, eq=False)
class _Job:
    """One export's inputs, checked."""

    annotations: AnnotationSet
    out: Path
    site_name: str
    mode: CamaMode
    radius_m: float
    elevation: np.ndarray | float
    """Our raster, or (no raster given) the one height of every map: the lifted elements' mean z."""


def export_cama_release(
    annotations: AnnotationSet,
    out: Path,
    *,
    dataset: Dataset,
    poses: PoseLookup,
    scenes: Sequence[str],
    site_name: str,
    mode: CamaMode = "clip",
    elevation: np.ndarray | None = None,
    observed_radius_m: float = DEFAULT_OBSERVED_RADIUS_M,
    show_progress: bool = False,
) -> CamaReleaseResult:
    """Write the release layout of `scenes` (their images only) into the folder `out` (ValueError on bad input,
    before anything is written, where it can be known then). `elevation` is our (H, W) raster in the annotation
    set's georeference (global z, NaN unobserved); without one every map is the mean z of the lifted elements
    (all cells marked filled), and without lifted elements the export is refused (ValueError)."""
    job = _job(annotations, Path(out), site_name, mode, elevation, observed_radius_m)
    cameras = {scene.name: scene_camera_poses(scene, poses) for scene in _scenes(dataset, scenes)}
    with StageProgress("cama export", logger=logger, enabled=show_progress) as progress:
        task = progress.add_task("scenes", total=len(cameras))
        export = _export_site if mode == "site" else _export_clip
        result = export(job, cameras, lambda: progress.advance(task))
    logger.info("CAMA release (%s mode) of %d scenes written to %s", mode, len(result.scenes), job.out)
    return result


def _export_clip(
    job: _Job, cameras: dict[str, list[CameraPose]], advance: Callable[[], object]
) -> CamaReleaseResult:
    """Clip mode: each scene's own map (elevation, labels), odometry and sidecar, one map in memory at a time."""
    written = []
    for scene, scene_cameras in cameras.items():
        frame = ReleaseFrame.around(_positions(scene_cameras), MAP_SIDE_M["clip"])
        elevation_map = _map_elevation(job, frame, f"scene {scene}")
        folder = job.out / ALL_CLIPS / scene
        elevation_map.write(folder / SCENE_ELEVATION, folder / SCENE_FILLED)
        filled, source = elevation_map.filled_cells, elevation_map.source
        del elevation_map
        written.append(_write_scene(job, scene, scene_cameras, frame, filled, source))
        advance()
    return CamaReleaseResult(job.out, "clip", job.site_name, tuple(written), elevation_source=_source(job))


def _export_site(
    job: _Job, cameras: dict[str, list[CameraPose]], advance: Callable[[], object]
) -> CamaReleaseResult:
    """Site mode: the site map and site2clip files, then each scene's cut and odometry in the site's frame."""
    every = [camera for scene_cameras in cameras.values() for camera in scene_cameras]
    frame = ReleaseFrame.around(_positions(every), MAP_SIDE_M["site"])
    site2clip = job.out / SITE2CLIP
    site = job.site_name
    npy, png = site2clip / f"{site}{SITE_ELEVATION_SUFFIX}", site2clip / f"{site}{SITE_FILLED_SUFFIX}"
    elevation_map = _map_elevation(job, frame, f"site {site}")
    elevation_map.write(npy, png)
    filled, source = elevation_map.filled_cells, elevation_map.source
    del elevation_map
    labels = site2clip / f"{site}{SITE_LABELS_SUFFIX}"
    square = _site_square(job, frame)
    site_instances = _write_labels(job, labels, cut_elements(job.annotations, square), frame)
    sidecar = site2clip / f"{site}{SITE_SIDECAR_SUFFIX}"
    _write_sidecar(job, sidecar, frame, scene=None, filled_png=png.name, source=source)
    index = job.out / SITE2CLIP_JSON
    atomic_write_bytes(index, json.dumps({site: list(cameras)}, indent=1).encode("utf-8"))
    written = []
    for scene, scene_cameras in cameras.items():
        folder = job.out / ALL_CLIPS / scene
        _link_or_copy(npy, folder / SCENE_ELEVATION)
        _link_or_copy(png, folder / SCENE_FILLED)
        written.append(_write_scene(job, scene, scene_cameras, frame, filled, source))
        advance()
    return CamaReleaseResult(
        job.out, "site", site, tuple(written), (labels, npy, sidecar, png, index), site_instances, source
    )


def _write_scene(
    job: _Job,
    scene: str,
    cameras: list[CameraPose],
    frame: ReleaseFrame,
    filled_cells: int,
    source: ElevationSource,
) -> CamaSceneWritten:
    """A scene folder's labels (its cut), odometry and sidecar; its elevation files are already written."""
    folder = job.out / ALL_CLIPS / scene
    origin = job.annotations.georeference.site_origin_xy
    trajectories = []
    for channel in sorted({camera.image.channel for camera in cameras}):
        track = [
            camera.global_from_cam.translation[:2] for camera in cameras if camera.image.channel == channel
        ]
        trajectories.append(np.asarray(track) - np.asarray(origin))
    square = _site_square(job, frame)
    outside = sum(not square.covers(shapely.Point(xy)) for track in trajectories for xy in track)
    if outside:
        logger.warning(
            "scene %s: %d camera positions lie outside the %g m map centred at global %s; the labels they saw "
            "are cut at the map's edge",
            scene,
            outside,
            frame.side_m,
            frame.origin_global[:2],
        )
    region = observed_range(trajectories, job.radius_m, square)
    instances = _write_labels(job, folder / MAP_LABELS, cut_elements(job.annotations, region), frame)
    rows = write_odometry(cameras, folder / ODOMETRY_DIR, prefix=ODOMETRY_PREFIX[job.mode], frame=frame)
    _write_sidecar(job, folder / SCENE_SIDECAR, frame, scene=scene, filled_png=FILLED_PNG, source=source)
    return CamaSceneWritten(scene, folder, instances, sum(rows.values()), filled_cells)


def _write_labels(job: _Job, path: Path, pieces: list[Piece], frame: ReleaseFrame) -> int:
    """map_labels.json of the pieces (site metres) in the frame's pixels, densified to at most
    LABEL_SPACING_M between points; the instance count."""
    origin = np.asarray(job.annotations.georeference.site_origin_xy)
    instances = [
        cama_instance(
            piece.instance_id,
            piece.cls,
            frame.uv_from_global(densify(piece.xy, LABEL_SPACING_M) + origin),
            track_id=piece.track_id,
            element_id=piece.element_id,
        )
        for piece in pieces
    ]
    labels = validated_instances(instances, path)
    atomic_write_bytes(path, json.dumps(labels, indent=1).encode("utf-8"))
    return len(labels)


def _write_sidecar(
    job: _Job, path: Path, frame: ReleaseFrame, *, scene: str | None, filled_png: str, source: ElevationSource
) -> None:
    """Our version 2 georeference sidecar of one map."""
    sidecar = CamaReleaseGeoreference(
        site_id=job.site_name,
        scene=scene,
        mode=job.mode,
        georeference=job.annotations.georeference,
        world_origin_global=frame.origin_global,
        map_side_m=frame.side_m,
        resolution_m=frame.resolution_m,
        cells=frame.cells,
        observed_radius_m=job.radius_m if scene is not None else None,
        elevation_filled=filled_png,
        elevation_source=source,
        label_spacing_m=LABEL_SPACING_M,
    )
    atomic_write_bytes(path, sidecar.model_dump_json(indent=2).encode("utf-8"))


def _map_elevation(job: _Job, frame: ReleaseFrame, where: str) -> ReleaseElevation:
    """The map's elevation: resampled from our raster, else the elements' mean z."""
    if isinstance(job.elevation, float):
        return constant_elevation(job.elevation, frame)
    return release_elevation(job.elevation, job.annotations.georeference, frame, where=where)


def _source(job: _Job) -> ElevationSource:
    return "elements-mean" if isinstance(job.elevation, float) else "raster"


def _site_square(job: _Job, frame: ReleaseFrame) -> shapely.Geometry:
    """The map square in site metres."""
    x0, y0 = job.annotations.georeference.site_origin_xy
    return shapely.affinity.translate(frame.square_global(), -x0, -y0)


def _positions(cameras: Sequence[CameraPose]) -> np.ndarray:
    """(N, 3) global camera positions."""
    return np.asarray([camera.global_from_cam.translation for camera in cameras], dtype=float)


def _link_or_copy(source: Path, target: Path) -> None:
    """`target` as a hard link to `source`, or an atomic copy where hard links fail."""
    target.parent.mkdir(parents=True, exist_ok=True)
    target.unlink(missing_ok=True)
    try:
        os.link(source, target)
    except OSError:
        fd, tmp_name = tempfile.mkstemp(dir=target.parent, prefix=f".{target.name}.", suffix=".tmp")
        os.close(fd)
        try:
            shutil.copyfile(source, tmp_name)
            os.replace(tmp_name, target)
        except BaseException:
            Path(tmp_name).unlink(missing_ok=True)
            raise


def _job(
    annotations: AnnotationSet,
    out: Path,
    site_name: str,
    mode: CamaMode,
    elevation: np.ndarray | None,
    radius_m: float,
) -> _Job:
    """The checked inputs; ValueError naming the argument."""
    if mode not in CAMA_MODES:
        raise ValueError(f"mode: expected one of {CAMA_MODES}, got {mode!r}")
    _check_name(site_name, "site_name")
    if not (np.isfinite(radius_m) and radius_m > 0):
        raise ValueError(f"observed_radius_m: expected a finite value > 0, got {radius_m}")
    if elevation is None:
        return _Job(annotations, out, site_name, mode, radius_m, _mean_element_z(annotations))
    raster = np.asarray(elevation)
    if raster.shape != annotations.georeference.shape:
        raise ValueError(
            f"elevation: shape {raster.shape} != the annotation set's georeference (height, width) "
            f"{annotations.georeference.shape}"
        )
    return _Job(annotations, out, site_name, mode, radius_m, raster)


def _mean_element_z(annotations: AnnotationSet) -> float:
    """The mean z of every lifted element point; ValueError naming the missing elevation when none is lifted."""
    zs = [xyz[:, 2] for element in annotations.elements if (xyz := element.xyz()) is not None]
    if not zs:
        raise ValueError(
            "elevation: no elevation raster given and no element is lifted (points_3d), so the release's "
            f"{ELEVATION_NPY} has no heights; pass the surface stage's elevation raster (or lift the elements)"
        )
    return float(np.mean(np.concatenate(zs)))


def _scenes(dataset: Dataset, names: Sequence[str]) -> list[Scene]:
    """The data set's scenes of these names, in the given order; ValueError naming unknown or repeated ones."""
    if isinstance(names, str) or not names:
        raise ValueError(f"scenes: expected a non-empty list of scene names, got {names!r}")
    repeated = sorted({name for name in names if list(names).count(name) > 1})
    if repeated:
        raise ValueError(f"scenes: repeated {repeated}")
    known = {scene.name: scene for scene in dataset.scenes}
    unknown = [name for name in names if name not in known]
    if unknown:
        raise ValueError(f"scenes: {unknown} not in the data set (scenes: {sorted(known)})")
    for name in names:
        _check_name(name, "scenes")
    return [known[name] for name in names]


def _check_name(name: str, what: str) -> None:
    """A name usable as one file or folder name; ValueError naming `what`."""
    if not isinstance(name, str) or not name or name in (".", "..") or any(c in name for c in "/\\\0"):
        raise ValueError(f"{what}: {name!r} is not usable as a folder or file name")
