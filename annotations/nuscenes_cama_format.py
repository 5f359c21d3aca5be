"""nuScenes-CAMAv2 export: a nuScenes root whose version folder holds the refined ego poses, so that any code
reading nuScenes (the official devkit's `NuScenes(version=..., dataroot=...)`, MapTR's converters, our own
`load_dataset`) trains on refined poses without changes.

Layout written into `out` (a fresh folder; the caller stages it and renames it into place):

    <out>/<version>-cama/           the source version folder's name + `-cama` (v1.0-mini -> v1.0-mini-cama)
        <table>.json                every file of the source version folder, unchanged: hard-linked where the
                                    file system allows (`link_tables`), else copied byte for byte
        ego_pose.json               rewritten: the same records (tokens, order, fields, JSON indentation) with
                                    `translation` and `rotation` of the refined global_from_ego (below)
        map_vectors.json            per sample (key frame), the map vectors in that sample's refined ego frame:
                                    a MapTR vectors file (`annotations.maptr_format`, `read_maptr` reads it)
        pose_sources.json           per ego_pose token its source (sfm, wigo+sfm, wigo, coarse), with counts
    <out>/<entry> -> <source root>/<entry>
                                    an absolute symbolic link for every other top-level entry of the source root
                                    (samples/, sweeps/, maps/, can_bus/, our mask folders, ...), so image paths
                                    in sample_data resolve; absolute so that the staged folder may be renamed or
                                    moved. Left out: the source's version folders (any folder with a scene.json,
                                    so the new root has one version and `load_dataset` finds it unasked), hidden
                                    entries, and any entry holding `out` itself.

Refined ego poses, per ego_pose record (nuScenes has one per sample_data):
- a camera image's record: the export's `PoseLookup` for that image (the SfM pose, WIGO corrected by SfM, ...);
  where the lookup has no refined pose (source `coarse`) the logged record is kept as it is.
- a non-camera record (lidar, radar): the correction `refined @ logged^-1` of the camera image nearest in time
  in the same scene (among those with a refined pose, within `max_borrow_gap_us`) applied to its own logged
  pose; its source is that image's, and pose_sources.json names the image (`correction_from`). None near: logged.
  The nearest image's correction rather than an interpolation: cameras fire at 12 Hz, so the nearest one is at
  most ~40 ms away, and the correction (a drift of the logged trajectory) changes little in that time.
- a record no sample_data refers to: logged. A record shared by several sample_data: the first camera image's.

Each sample's reference ego pose in map_vectors.json is its LIDAR_TOP key frame's (corrected) ego pose when it
has one, as nuScenes-reading converters take a sample's ego2global from LIDAR_TOP; else its CAM_FRONT key-frame
image's (the MapTR export's choice). The file records that pose per sample, so the frame is never ambiguous.
"""

import bisect
import json
import logging
import os
import shutil
import uuid
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from annotations.geometry import MAPTR_RANGE, Box
from annotations.maptr_format import POINTS_PER_VECTOR, EgoPose, build_maptr, sample_pose
from annotations.poses import POSE_SOURCES, PoseLookup, PoseSource
from annotations.schema import AnnotationSet
from cama_pipeline.data import Dataset, Frame, Pose
from cama_pipeline.data.errors import DatasetError
from cama_pipeline.data.tables import Table, read_table, table_path
from cama_pipeline.io import atomic_write_bytes, atomic_write_json
from cama_pipeline.progress import StageProgress

logger = logging.getLogger(__name__)

VERSION_SUFFIX = "-cama"
EGO_POSE = "ego_pose"
MAP_VECTORS = "map_vectors.json"
POSE_SOURCES_FILE = "pose_sources.json"
POSE_SOURCES_FORMAT: Literal["cama-studio-nuscenes-pose-sources"] = "cama-studio-nuscenes-pose-sources"
LIDAR_REFERENCE = "LIDAR_TOP"
CAMERA_MODALITY = "camera"
MAX_BORROW_GAP_US = 500_000
"""How far in time (microseconds) a non-camera record may borrow a camera image's correction."""


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


@dataclass(frozen=True)
class EgoPoseEntry:
    """The refined value of one ego_pose record and where it came from."""

    source: PoseSource
    global_from_ego: Pose | None
    """None: the logged record is kept as it is."""
    sample_data: str | None
    """The sample_data record using it (None: unreferenced)."""
    channel: str | None
    correction_from: str | None = None
    """For a non-camera record: the camera sample_data whose correction it took."""
    camera: bool = False
    """Whether the record is a camera image's (posed by the lookup itself)."""


@dataclass(frozen=True)
class _Correction:
    """A camera image's `refined @ logged^-1` at its capture time."""

    timestamp_us: int
    global_from_global: Pose
    source: PoseSource
    image: str


def cama_version(version: str) -> str:
    """The new version folder's name: the source's with `-cama` appended (v1.0-mini -> v1.0-mini-cama)."""
    return f"{version}{VERSION_SUFFIX}"


def _source_tables(dataset_root: Path, version: str) -> dict[str, Table]:
    """The tables the export reads, from the source's version folder; DatasetError naming what is missing."""
    version_dir = Path(dataset_root) / version
    if not Path(dataset_root).is_dir():
        raise DatasetError("data set root is not a folder", path=dataset_root)
    if not (version_dir / "scene.json").is_file():
        found = sorted(p.name for p in Path(dataset_root).iterdir() if p.is_dir())
        raise DatasetError(
            f"no version folder {version!r} with scene.json; folders found: {found}", path=version_dir
        )
    names = ("scene", "sample", "sample_data", EGO_POSE, "calibrated_sensor", "sensor")
    return {name: read_table(version_dir, name) for name in names}


def _sensor_channels(tables: dict[str, Table], version_dir: Path) -> dict[str, tuple[str, str]]:
    """sample_data token -> (channel, modality), through calibrated_sensor and sensor."""
    out = {}
    for token, record in tables["sample_data"].items():
        calibrated = tables["calibrated_sensor"].get(record["calibrated_sensor_token"])
        sensor = tables["sensor"].get(calibrated["sensor_token"]) if calibrated else None
        if sensor is None:
            detail = f"calibrated_sensor {record['calibrated_sensor_token']!r} or its sensor not found"
            raise DatasetError(
                detail,
                path=table_path(version_dir, "sample_data"),
                record=token,
                field="calibrated_sensor_token",
            )
        out[token] = (str(sensor["channel"]), str(sensor["modality"]))
    return out


def _logged_pose(tables: dict[str, Table], token: str, version_dir: Path) -> Pose:
    """The logged global_from_ego of an ego_pose record; DatasetError naming it when not a pose."""
    record = tables[EGO_POSE][token]
    try:
        return Pose(record["translation"], record["rotation"])
    except (TypeError, ValueError) as error:
        raise DatasetError(str(error), path=table_path(version_dir, EGO_POSE), record=token) from None


def _camera_entries(
    dataset: Dataset, tables: dict[str, Table], poses: PoseLookup, version_dir: Path
) -> tuple[dict[str, EgoPoseEntry], dict[str, list[_Correction]]]:
    """Entries of the camera images' ego_pose records, and per scene token the time-sorted corrections of
    those with a refined pose. DatasetError when the data set does not match the tables."""
    entries: dict[str, EgoPoseEntry] = {}
    corrections: dict[str, list[_Correction]] = {}
    sample_data = tables["sample_data"]
    for scene in dataset.scenes:
        found = corrections.setdefault(scene.token, [])
        for image in scene.all_images():
            if image.token not in sample_data:
                raise DatasetError(
                    f"camera image {image.token!r} of the data set is not in this table: the data set was not "
                    "loaded from this root",
                    path=table_path(version_dir, "sample_data"),
                )
            ego_pose_token = sample_data[image.token]["ego_pose_token"]
            sourced = poses(image)
            refined = None if sourced.source == "coarse" else sourced.global_from_ego
            entries.setdefault(
                ego_pose_token, EgoPoseEntry(sourced.source, refined, image.token, image.channel, camera=True)
            )
            if refined is not None:
                correction = refined @ image.global_from_ego.inverse()
                found.append(_Correction(image.timestamp_us, correction, sourced.source, image.token))
        found.sort(key=lambda c: (c.timestamp_us, c.image))
    return entries, corrections


def _nearest(corrections: list[_Correction], timestamp_us: int, max_gap_us: int) -> _Correction | None:
    """The correction nearest in time (the earlier one on a tie), None when none lies within max_gap_us."""
    times = [c.timestamp_us for c in corrections]
    after = bisect.bisect_left(times, timestamp_us)
    candidates = [c for c in corrections[max(after - 1, 0) : after + 1]]
    best = min(candidates, key=lambda c: abs(c.timestamp_us - timestamp_us), default=None)
    if best is None or abs(best.timestamp_us - timestamp_us) > max_gap_us:
        return None
    return best


def refined_ego_poses(
    dataset: Dataset,
    tables: dict[str, Table],
    poses: PoseLookup,
    version_dir: Path,
    *,
    max_borrow_gap_us: int = MAX_BORROW_GAP_US,
) -> dict[str, EgoPoseEntry]:
    """ego_pose token -> its refined value and source, for every record (the module docstring's rules)."""
    entries, corrections = _camera_entries(dataset, tables, poses, version_dir)
    channels = _sensor_channels(tables, version_dir)
    sample_data_path = table_path(version_dir, "sample_data")
    dataset_images = {image.token for image in dataset.camera_images()}
    for token, record in tables["sample_data"].items():
        channel, modality = channels[token]
        ego_pose_token = record["ego_pose_token"]
        if ego_pose_token not in tables[EGO_POSE]:
            raise DatasetError(
                f"token {ego_pose_token!r} not found in ego_pose.json",
                path=sample_data_path,
                record=token,
                field="ego_pose_token",
            )
        if modality == CAMERA_MODALITY and token not in dataset_images:
            raise DatasetError(
                "camera record missing from the data set: the data set was not loaded from this root",
                path=sample_data_path,
                record=token,
            )
        if ego_pose_token in entries:
            continue
        sample = tables["sample"].get(record["sample_token"])
        if sample is None:
            raise DatasetError(
                f"sample {record['sample_token']!r} not found",
                path=sample_data_path,
                record=token,
                field="sample_token",
            )
        near = _nearest(corrections.get(sample["scene_token"], []), record["timestamp"], max_borrow_gap_us)
        if near is None:
            entries[ego_pose_token] = EgoPoseEntry("coarse", None, token, channel)
        else:
            logged = _logged_pose(tables, ego_pose_token, version_dir)
            refined = near.global_from_global @ logged
            entries[ego_pose_token] = EgoPoseEntry(near.source, refined, token, channel, near.image)
    for ego_pose_token in tables[EGO_POSE]:
        entries.setdefault(ego_pose_token, EgoPoseEntry("coarse", None, None, None))
    return entries


def _json_indent(text: str) -> int | None:
    """The indentation `json.dumps` wrote a list of records with: None for one line, else the second line's
    leading spaces (0 for nuScenes' own files)."""
    lines = text.split("\n", 2)
    if len(lines) < 2:
        return None
    return len(lines[1]) - len(lines[1].lstrip(" "))


def ego_pose_json(version_dir: Path, table: Table, entries: dict[str, EgoPoseEntry]) -> bytes:
    """The source's ego_pose.json with refined translation and rotation: same records, order, fields and
    indentation; records kept as logged come out as they were read."""
    text = table_path(version_dir, EGO_POSE).read_text(encoding="utf-8")
    records = []
    for token, record in table.items():
        pose = entries[token].global_from_ego
        if pose is None:
            records.append(record)
            continue
        refined = dict(record)
        refined["translation"] = [float(v) for v in pose.translation]
        refined["rotation"] = [float(v) for v in pose.rotation]
        records.append(refined)
    out = json.dumps(records, indent=_json_indent(text))
    return (out + "\n" if text.endswith("\n") else out).encode("utf-8")


def pose_sources_json(
    entries: dict[str, EgoPoseEntry], *, version: str, source_version: str, max_borrow_gap_us: int
) -> dict[str, Any]:
    """pose_sources.json: counts per source and, per ego_pose token, its source, sample_data, channel, the
    camera image a non-camera record took its correction from, and whether the logged value was kept."""
    counts = Counter(entry.source for entry in entries.values())
    return {
        "format": POSE_SOURCES_FORMAT,
        "format_version": 1,
        "version": version,
        "source_version": source_version,
        "non_camera_records": "logged pose corrected by the nearest camera image's refined @ logged^-1 "
        "(same scene, within max_borrow_gap_us); none near: logged",
        "max_borrow_gap_us": max_borrow_gap_us,
        "counts": {source: counts.get(source, 0) for source in POSE_SOURCES},
        "ego_poses": {
            token: {
                "source": entry.source,
                "sample_data": entry.sample_data,
                "channel": entry.channel,
                "correction_from": entry.correction_from,
                "logged": entry.global_from_ego is None,
            }
            for token, entry in entries.items()
        },
    }


def _ego(pose: Pose) -> EgoPose:
    """The MapTR file's ego pose of a Pose."""
    return EgoPose(translation=tuple(pose.translation.tolist()), rotation=tuple(pose.rotation.tolist()))


def reference_poses(
    entries: dict[str, EgoPoseEntry], tables: dict[str, Table], poses: PoseLookup, version_dir: Path
) -> Callable[[Frame], tuple[EgoPose, PoseSource]]:
    """A sample's reference ego pose for map_vectors.json: its LIDAR_TOP key frame's record as written to
    ego_pose.json when it has one, else the MapTR export's (CAM_FRONT key-frame image's, from `poses`)."""
    channels = _sensor_channels(tables, version_dir)
    lidar: dict[str, str] = {}
    for token, record in tables["sample_data"].items():
        if channels[token][0] == LIDAR_REFERENCE and record["is_key_frame"] is True:
            lidar.setdefault(record["sample_token"], record["ego_pose_token"])

    def frame_pose(frame: Frame) -> tuple[EgoPose, PoseSource]:
        token = lidar.get(frame.token)
        if token is None:
            return sample_pose(frame, poses)
        entry = entries[token]
        pose = entry.global_from_ego or _logged_pose(tables, token, version_dir)
        return _ego(pose), entry.source

    return frame_pose


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
    show_progress: bool = False,
) -> NuscenesCamaResult:
    """Write the nuScenes-CAMAv2 root into `out` (the module docstring's layout), ego poses from `poses`.

    `dataset` is the data set loaded from `dataset_root`; its version folder is the one exported.
    `link_tables`: hard-link the unchanged tables where the file system allows (else copy).
    `max_borrow_gap_us`: how far a non-camera record may take a camera image's correction.
    `box`, `n_points`: the map vectors' ego-frame clip box and points per vector (as the MapTR export's).
    Everything is read and computed before the first file is written. ValueError (DatasetError for the
    source) naming the file: no such version folder, a bad table, a data set not loaded from this root, a
    non-empty `out`.
    """
    dataset_root, out = Path(dataset_root).absolute(), Path(out).absolute()
    _check_out(out)
    source_dir = dataset_root / dataset.version
    tables = _source_tables(dataset_root, dataset.version)
    entries = refined_ego_poses(dataset, tables, poses, source_dir, max_borrow_gap_us=max_borrow_gap_us)
    ego_pose = ego_pose_json(source_dir, tables[EGO_POSE], entries)
    frame_pose = reference_poses(entries, tables, poses, source_dir)
    with StageProgress("cama export", logger=logger, enabled=show_progress) as progress:
        task = progress.add_task("map vectors", total=sum(len(s.frames) for s in dataset.scenes))
        vectors = build_maptr(
            annotations,
            dataset,
            poses=poses,
            box=box,
            n_points=n_points,
            frame_pose=frame_pose,
            on_sample=lambda: progress.advance(task),
        )
    version = cama_version(dataset.version)
    sources = pose_sources_json(
        entries, version=version, source_version=dataset.version, max_borrow_gap_us=max_borrow_gap_us
    )
    version_dir = out / version
    version_dir.mkdir(parents=True, exist_ok=True)
    linked, copied = _place_version_files(source_dir, version_dir, link=link_tables)
    atomic_write_bytes(version_dir / f"{EGO_POSE}.json", ego_pose)
    atomic_write_bytes(version_dir / MAP_VECTORS, vectors.model_dump_json(by_alias=True, indent=1).encode())
    atomic_write_json(version_dir / POSE_SOURCES_FILE, sources, indent=1)
    entries_linked = _link_root_entries(dataset_root, out)
    result = NuscenesCamaResult(
        root=out,
        version=version,
        source_version=dataset.version,
        counts=dict(sources["counts"]),
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
