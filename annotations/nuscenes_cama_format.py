"""nuScenes-CAMAv2 export: a nuScenes root whose version folder holds the refined ego poses, so that any code
reading nuScenes (the official devkit's `NuScenes(version=..., dataroot=...)`, MapTR's converters, our own
`load_dataset`) trains on refined poses without changes.

Layout written into `out` (a fresh folder; the caller stages it and renames it into place):

    <out>/<version>-cama/           the source version folder's name + `-cama` (v1.0-mini -> v1.0-mini-cama)
        <table>.json                every file of the source version folder, unchanged: hard-linked where the
                                    file system allows (`link_tables`), else copied byte for byte
        ego_pose.json               rewritten: the same records (tokens, order, fields, JSON indentation) with
                                    `translation` and `rotation` of the refined global_from_ego (below)
        map_vectors.json            per sample (key frame) of the exported scenes, the map vectors in that
                                    sample's refined ego frame: a MapTR vectors file (`annotations.maptr_format`,
                                    `read_maptr` reads it). Samples of other scenes are left out, not written
                                    with no vectors: a scene nobody annotated is not a road without markings,
                                    and another city's scenes share the site's coordinates (each city has its
                                    own map frame), so the site's vectors would land in them
        pose_sources.json           per ego_pose token its source (sfm, wigo+sfm, wigo, coarse), with counts
    <out>/<entry> -> <source root>/<entry>
                                    an absolute symbolic link for every other top-level entry of the source root
                                    (samples/, sweeps/, maps/, can_bus/, our mask folders, ...), so image paths
                                    in sample_data resolve; absolute so that the staged folder may be renamed or
                                    moved. Left out: the source's version folders (any folder with a scene.json,
                                    so the new root has one version and `load_dataset` finds it unasked), hidden
                                    entries, and any entry holding `out` itself.

The ego poses (the rules for camera, non-camera and unreferenced records): `annotations.nuscenes_cama_poses`.

Each sample's reference ego pose in map_vectors.json is its LIDAR_TOP key frame's (corrected) ego pose when it
has one, as nuScenes-reading converters take a sample's ego2global from LIDAR_TOP; else its CAM_FRONT key-frame
image's (the MapTR export's choice). The file records that pose per sample, so the frame is never ambiguous.
"""

import logging
import os
import shutil
import uuid
from collections.abc import Callable, Collection
from dataclasses import dataclass
from functools import partial
from pathlib import Path

from annotations.geometry import MAPTR_RANGE, Box
from annotations.maptr_format import POINTS_PER_VECTOR, EgoPose, build_maptr, sample_pose
from annotations.nuscenes_cama_poses import (
    EGO_POSE,
    EXPORT_TABLES,
    MAX_BORROW_GAP_US,
    EgoPoseEntry,
    logged_pose,
    pose_sources_chunks,
    pose_sources_header,
    refined_ego_poses,
    sensor_channels,
    source_tables,
    write_ego_pose_json,
)
from annotations.poses import PoseLookup, PoseSource
from annotations.schema import AnnotationSet
from cama_pipeline.data import Dataset, Frame, Pose
from cama_pipeline.data.tables import Table
from cama_pipeline.io import atomic_write_bytes, atomic_write_chunks
from cama_pipeline.progress import StageProgress

logger = logging.getLogger(__name__)

VERSION_SUFFIX = "-cama"
MAP_VECTORS = "map_vectors.json"
POSE_SOURCES_FILE = "pose_sources.json"
LIDAR_REFERENCE = "LIDAR_TOP"


@dataclass(frozen=True)
class NuscenesCamaResult:
    """What an export wrote: where, and how many ego poses came from each source."""

    root: Path
    """The new nuScenes root (`out`)."""
    version: str
    """The new version folder's name (`<source version>-cama`)."""
    source_version: str
    """The source's version folder name."""
    counts: dict[str, int]
    """ego_pose records per source (sfm, wigo+sfm, wigo, coarse), every source listed."""
    camera_records: int
    """ego_pose records of camera images (posed by the lookup; kept as logged where it had no refined pose)."""
    borrowed_records: int
    """Non-camera ego_pose records corrected by a camera image's correction."""
    kept_records: int
    """ego_pose records left as logged (source coarse: no refined pose, no camera near, or unreferenced)."""
    samples: int
    """Samples in map_vectors.json."""
    vectors: int
    """Map vectors over all samples."""
    tables_linked: int
    """Files of the version folder hard-linked to the source's."""
    tables_copied: int
    """Files of the version folder copied (across file systems, or `link_tables=False`)."""
    linked_entries: tuple[str, ...]
    """Top-level entries of the source root linked into the new root."""

    @property
    def version_dir(self) -> Path:
        """The new version folder."""
        return self.root / self.version


def cama_version(version: str) -> str:
    """The new version folder's name: the source's with `-cama` appended (v1.0-mini -> v1.0-mini-cama)."""
    return f"{version}{VERSION_SUFFIX}"


def _ego(pose: Pose) -> EgoPose:
    """The MapTR file's ego pose of a Pose."""
    return EgoPose(translation=tuple(pose.translation.tolist()), rotation=tuple(pose.rotation.tolist()))


def reference_poses(
    entries: dict[str, EgoPoseEntry],
    tables: dict[str, Table],
    poses: PoseLookup,
    version_dir: Path,
    channels: dict[str, tuple[str, str]],
) -> Callable[[Frame], tuple[EgoPose, PoseSource]]:
    """A sample's reference ego pose for map_vectors.json: its LIDAR_TOP key frame's record as written to
    ego_pose.json when it has one, else the MapTR export's (CAM_FRONT key-frame image's, from `poses`).
    `channels`: the tables' `sensor_channels`."""
    lidar: dict[str, str] = {}
    for token, record in tables["sample_data"].items():
        if channels[token][0] == LIDAR_REFERENCE and record["is_key_frame"] is True:
            lidar.setdefault(record["sample_token"], record["ego_pose_token"])

    def frame_pose(frame: Frame) -> tuple[EgoPose, PoseSource]:
        token = lidar.get(frame.token)
        if token is None:
            return sample_pose(frame, poses)
        entry = entries[token]
        pose = entry.global_from_ego or logged_pose(tables, token, version_dir)
        return _ego(pose), entry.source

    return frame_pose


def _advancer(progress: StageProgress, description: str, total: int) -> Callable[[int], None]:
    """A new bar of `total` steps, and the function that advances it by n."""
    task = progress.add_task(description, total=total)
    return partial(progress.advance, task)


def _check_out(out: Path) -> None:
    """`out` must be a new or empty folder (the caller stages it); ValueError naming it otherwise."""
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise ValueError(f"{out}: the output must be a new or empty folder")


def _place_file(source: Path, target: Path, *, link: bool) -> bool:
    """Put `source`'s bytes at `target`: a hard link when `link` and the file system allows it (True), else a
    copy written beside it and renamed into place (False)."""
    if link:
        try:
            os.link(source, target)
            return True
        except OSError:
            pass
    temporary = target.with_name(f".{target.name}.{uuid.uuid4().hex}.tmp")
    try:
        shutil.copyfile(source, temporary)
        os.replace(temporary, target)
    except BaseException:
        temporary.unlink(missing_ok=True)
        raise
    return False


def _place_version_files(source_dir: Path, version_dir: Path, *, link: bool) -> tuple[int, int]:
    """Every entry of the source version folder but the files this export writes: files linked or copied,
    folders linked (absolute symbolic links). Returns (linked, copied) file counts."""
    written = {f"{EGO_POSE}.json", MAP_VECTORS, POSE_SOURCES_FILE}
    linked = copied = 0
    for entry in sorted(source_dir.iterdir()):
        if entry.name in written or entry.name.startswith("."):
            continue
        target = version_dir / entry.name
        if entry.is_dir():
            os.symlink(entry.resolve(), target, target_is_directory=True)
        elif _place_file(entry, target, link=link):
            linked += 1
        else:
            copied += 1
    return linked, copied


def _link_root_entries(dataset_root: Path, out: Path) -> tuple[str, ...]:
    """Absolute symbolic links in `out` to the source root's top-level entries but its version folders, hidden
    entries and any entry holding `out` (the module docstring); returns their names."""
    names = []
    inside = out.resolve()
    for entry in sorted(dataset_root.iterdir()):
        if entry.name.startswith(".") or (entry / "scene.json").is_file():
            continue
        target = entry.resolve()
        if inside == target or inside.is_relative_to(target):
            continue
        os.symlink(target, out / entry.name, target_is_directory=entry.is_dir())
        names.append(entry.name)
    return tuple(names)


def export_nuscenes_cama(
    annotations: AnnotationSet,
    dataset_root: Path,
    dataset: Dataset,
    out: Path,
    *,
    poses: PoseLookup,
    link_tables: bool = True,
    max_borrow_gap_us: int = MAX_BORROW_GAP_US,
    box: Box = MAPTR_RANGE,
    n_points: int = POINTS_PER_VECTOR,
    scenes: Collection[str] | None = None,
    show_progress: bool = False,
) -> NuscenesCamaResult:
    """Write the nuScenes-CAMAv2 root into `out` (the module docstring's layout), ego poses from `poses`.

    `dataset` is the data set loaded from `dataset_root`, whole or by scene (`load_dataset(root, scenes=...)`:
    the records of the scenes left out keep their logged poses); its version folder is the one exported.
    `scenes`: the scenes whose samples get map vectors (names of loaded scenes); None: every loaded scene.
    `link_tables`: hard-link the unchanged tables where the file system allows (else copy).
    `max_borrow_gap_us`: how far a non-camera record may take a camera image's correction.
    `box`, `n_points`: the map vectors' ego-frame clip box and points per vector (as the MapTR export's).
    Everything is read and computed before the first file is written. ValueError (DatasetError for the
    source) naming the file: no such version folder, a bad table, a data set not loaded from this root, a
    non-empty `out`.
    """
    if max_borrow_gap_us < 0:
        raise ValueError(f"max_borrow_gap_us: must be >= 0, got {max_borrow_gap_us}")
    dataset_root, out = Path(dataset_root).absolute(), Path(out).absolute()
    _check_out(out)
    loaded = [scene.name for scene in dataset.scenes]
    unknown = sorted(set(scenes or ()) - set(loaded))
    if unknown:
        raise ValueError(f"scenes {unknown}: not among the loaded scenes {loaded}")
    exported = loaded if scenes is None else [name for name in loaded if name in scenes]
    source_dir = dataset_root / dataset.version
    with StageProgress("cama export", logger=logger, enabled=show_progress) as progress:
        tables = source_tables(
            dataset_root, dataset.version, on_table=_advancer(progress, "tables", len(EXPORT_TABLES))
        )
        channels = sensor_channels(tables, source_dir)
        entries = refined_ego_poses(
            dataset,
            tables,
            poses,
            source_dir,
            max_borrow_gap_us=max_borrow_gap_us,
            channels=channels,
            on_records=_advancer(progress, "ego poses", len(tables["sample_data"])),
        )
        frame_pose = reference_poses(entries, tables, poses, source_dir, channels)
        total = sum(len(scene.frames) for scene in dataset.scenes if scene.name in exported)
        vectors = build_maptr(
            annotations,
            dataset,
            poses=poses,
            box=box,
            n_points=n_points,
            frame_pose=frame_pose,
            on_sample=partial(_advancer(progress, "map vectors", total), 1),
            scenes=exported,
        )
        version = cama_version(dataset.version)
        header = pose_sources_header(
            entries, version=version, source_version=dataset.version, max_borrow_gap_us=max_borrow_gap_us
        )
        version_dir = out / version
        version_dir.mkdir(parents=True, exist_ok=True)
        linked, copied = _place_version_files(source_dir, version_dir, link=link_tables)
        write_ego_pose_json(
            version_dir / f"{EGO_POSE}.json",
            source_dir,
            tables[EGO_POSE],
            entries,
            on_records=_advancer(progress, f"{EGO_POSE}.json", len(tables[EGO_POSE])),
        )
        atomic_write_bytes(
            version_dir / MAP_VECTORS, vectors.model_dump_json(by_alias=True, indent=1).encode()
        )
        written = _advancer(progress, POSE_SOURCES_FILE, len(entries))
        atomic_write_chunks(
            version_dir / POSE_SOURCES_FILE, pose_sources_chunks(header, entries, on_records=written)
        )
    entries_linked = _link_root_entries(dataset_root, out)
    result = NuscenesCamaResult(
        root=out,
        version=version,
        source_version=dataset.version,
        counts=dict(header["counts"]),
        camera_records=sum(1 for entry in entries.values() if entry.camera),
        borrowed_records=sum(1 for entry in entries.values() if entry.correction_from is not None),
        kept_records=sum(1 for entry in entries.values() if entry.global_from_ego is None),
        samples=len(vectors.samples),
        vectors=sum(len(sample.vectors) for sample in vectors.samples),
        tables_linked=linked,
        tables_copied=copied,
        linked_entries=entries_linked,
    )
    logger.info("nuscenes-cama: %s, ego poses per source %s", version_dir, result.counts)
    return result
