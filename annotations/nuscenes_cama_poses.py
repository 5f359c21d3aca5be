"""The ego poses of the nuScenes-CAMAv2 export (`annotations.nuscenes_cama_format`): every ego_pose record of the
source's version folder with its refined global_from_ego and source, the rewritten ego_pose.json and
pose_sources.json.

Refined ego poses, per ego_pose record (nuScenes has one per sample_data):
- a camera image's record: the export's `PoseLookup` for that image (the SfM pose, WIGO corrected by SfM, ...);
  where the lookup has no refined pose (source `coarse`) the logged record is kept as it is.
- a non-camera record (lidar, radar): the correction `refined @ logged^-1` of the camera image nearest in time
  in the same scene (among those with a refined pose, within `max_borrow_gap_us`) applied to its own logged
  pose; its source is that image's, and pose_sources.json names the image (`correction_from`). None near: logged.
  The nearest image's correction rather than an interpolation: cameras fire at 12 Hz, so the nearest one is at
  most ~40 ms away, and the correction (a drift of the logged trajectory) changes little in that time.
- a record no sample_data refers to: logged. A record shared by several sample_data: the first camera image's.
- every record of a scene the data set was not loaded with (`load_dataset(root, scenes=...)`, as `cama export`
  loads the sites' scenes of a large data set): logged, since nothing refined it.

pose_sources.json: {"format": "cama-studio-nuscenes-pose-sources", "format_version": 1, "version",
"source_version", "non_camera_records" (the rule, in words), "max_borrow_gap_us", "counts": {source: records},
"ego_poses": {ego_pose token: {"source", "sample_data", "channel", "correction_from", "logged"}}}, `logged` true
where the record was kept as it was read.
"""

import bisect
import itertools
import json
import os
from collections import Counter
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from annotations.poses import POSE_SOURCES, PoseLookup, PoseSource
from cama_pipeline.data import Dataset, Pose
from cama_pipeline.data.errors import DatasetError
from cama_pipeline.data.schema import CAMERA_MODALITY
from cama_pipeline.data.tables import Table, read_table, table_path
from cama_pipeline.io import atomic_write_chunks
from cama_pipeline.iterables import chunked, counted

EGO_POSE = "ego_pose"
POSE_SOURCES_FORMAT: Literal["cama-studio-nuscenes-pose-sources"] = "cama-studio-nuscenes-pose-sources"
SAMPLE_DATA_FIELDS = (
    "token",
    "sample_token",
    "ego_pose_token",
    "calibrated_sensor_token",
    "timestamp",
    "is_key_frame",
)
"""The fields of sample_data the export reads; the others (file names, sizes, links) are dropped as the table is
parsed: on nuScenes trainval that halves the memory its 2.6 million records take."""
MAX_BORROW_GAP_US = 500_000
"""How far in time (microseconds) a non-camera record may borrow a camera image's correction."""


@dataclass(frozen=True, slots=True)
class EgoPoseEntry:
    """The refined value of one ego_pose record and where it came from (slots: nuScenes trainval has 2.6 million
    of them)."""

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


EXPORT_TABLES = ("scene", "sample", EGO_POSE, "calibrated_sensor", "sensor", "sample_data")
"""The tables the export reads, in the order `source_tables` reads them."""


def source_tables(
    dataset_root: Path, version: str, *, on_table: Callable[[int], None] | None = None
) -> dict[str, Table]:
    """The tables the export reads (`EXPORT_TABLES`), from the source's version folder; DatasetError naming what
    is missing. `on_table(1)` after each table (a progress bar: on nuScenes trainval they take about 20 s)."""
    version_dir = Path(dataset_root) / version
    if not Path(dataset_root).is_dir():
        raise DatasetError("data set root is not a folder", path=dataset_root)
    if not (version_dir / "scene.json").is_file():
        found = sorted(p.name for p in Path(dataset_root).iterdir() if p.is_dir())
        raise DatasetError(
            f"no version folder {version!r} with scene.json; folders found: {found}", path=version_dir
        )
    tables = {}
    for name in EXPORT_TABLES:
        tables[name] = read_table(
            version_dir, name, keep=SAMPLE_DATA_FIELDS if name == "sample_data" else None
        )
        if on_table is not None:
            on_table(1)
    return tables


def sensor_channels(tables: dict[str, Table], version_dir: Path) -> dict[str, tuple[str, str]]:
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


def logged_pose(tables: dict[str, Table], token: str, version_dir: Path) -> Pose:
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
    best = min(
        corrections[max(after - 1, 0) : after + 1],
        key=lambda c: abs(c.timestamp_us - timestamp_us),
        default=None,
    )
    if best is None or abs(best.timestamp_us - timestamp_us) > max_gap_us:
        return None
    return best


def _scene_token(tables: dict[str, Table], token: str, version_dir: Path) -> str:
    """The scene of a sample_data record, through its sample; DatasetError naming it when not found."""
    sample = tables["sample"].get(tables["sample_data"][token]["sample_token"])
    if sample is None:
        raise DatasetError(
            "sample not found",
            path=table_path(version_dir, "sample_data"),
            record=token,
            field="sample_token",
        )
    return str(sample["scene_token"])


def _borrowed(
    tables: dict[str, Table],
    token: str,
    channel: str,
    corrections: list[_Correction],
    max_gap_us: int,
    version_dir: Path,
) -> EgoPoseEntry:
    """A non-camera record's entry: its logged pose corrected by the nearest camera image's correction."""
    record = tables["sample_data"][token]
    timestamp = record["timestamp"]
    if isinstance(timestamp, bool) or not isinstance(timestamp, int):
        detail = f"expected an integer, got {timestamp!r}"
        raise DatasetError(
            detail, path=table_path(version_dir, "sample_data"), record=token, field="timestamp"
        )
    near = _nearest(corrections, timestamp, max_gap_us)
    if near is None:
        return EgoPoseEntry("coarse", None, token, channel)
    refined = near.global_from_global @ logged_pose(tables, record["ego_pose_token"], version_dir)
    return EgoPoseEntry(near.source, refined, token, channel, near.image)


def refined_ego_poses(
    dataset: Dataset,
    tables: dict[str, Table],
    poses: PoseLookup,
    version_dir: Path,
    *,
    max_borrow_gap_us: int = MAX_BORROW_GAP_US,
    channels: dict[str, tuple[str, str]] | None = None,
    on_records: Callable[[int], None] | None = None,
) -> dict[str, EgoPoseEntry]:
    """ego_pose token -> its refined value and source, for every record (the module docstring's rules).
    `channels`: `sensor_channels` of the tables when the caller has them; `on_records(n)` as sample_data records
    are done (a progress bar)."""
    entries, corrections = _camera_entries(dataset, tables, poses, version_dir)
    channels = sensor_channels(tables, version_dir) if channels is None else channels
    sample_data_path = table_path(version_dir, "sample_data")
    loaded_scenes = {scene.token for scene in dataset.scenes}
    for token, record in counted(tables["sample_data"].items(), on_records):
        channel, modality = channels[token]
        ego_pose_token = record["ego_pose_token"]
        if not isinstance(ego_pose_token, str) or ego_pose_token not in tables[EGO_POSE]:
            raise DatasetError(
                f"token {ego_pose_token!r} not found in ego_pose.json",
                path=sample_data_path,
                record=token,
                field="ego_pose_token",
            )
        if ego_pose_token in entries:
            continue
        scene = _scene_token(tables, token, version_dir)
        if modality == CAMERA_MODALITY and scene in loaded_scenes:  # else: a scene left out of the load
            raise DatasetError(
                "camera record missing from the data set: the data set was not loaded from this root",
                path=sample_data_path,
                record=token,
            )
        near = corrections.get(scene, [])
        entries[ego_pose_token] = _borrowed(tables, token, channel, near, max_borrow_gap_us, version_dir)
    for ego_pose_token in tables[EGO_POSE]:
        entries.setdefault(ego_pose_token, EgoPoseEntry("coarse", None, None, None))
    return entries


def json_layout(path: Path) -> tuple[int | None, bool]:
    """(indent, trailing newline) of a JSON list of records as `json.dumps` wrote it, read from the file's head and
    its last byte (not the whole file: ego_pose.json is 0.4 GB on nuScenes trainval). Indent None: one line; else
    the second line's leading spaces (0 for nuScenes' own files)."""
    with open(path, "rb") as handle:
        head = handle.read(1 << 16)
        size = handle.seek(0, os.SEEK_END)
        handle.seek(max(size - 1, 0))
        newline_at_end = handle.read(1) == b"\n"
    first_newline = head.find(b"\n")
    if first_newline < 0 or first_newline == size - 1:
        return None, newline_at_end
    second = head[first_newline + 1 :]
    return len(second) - len(second.lstrip(b" ")), newline_at_end


def json_list_chunks(records: Iterable[Any], indent: int | None, *, batch: int = 4096) -> Iterator[str]:
    """The text `json.dumps(list(records), indent=indent)` would give, in pieces of `batch` records (each piece
    encoded by one `json.dumps` of the batch, its brackets cut off): a list of millions of records is written
    without holding it, or its text, whole."""
    opening, closing, separator = ("[", "]", ", ") if indent is None else ("[\n", "\n]", ",\n")
    started = False
    for chunk in chunked(records, batch):
        inner = json.dumps(chunk, indent=indent)[len(opening) : -len(closing)]
        yield separator + inner if started else opening + inner
        started = True
    yield closing if started else "[]"


def refined_records(
    table: Table, entries: dict[str, EgoPoseEntry], on_records: Callable[[int], None] | None = None
) -> Iterator[dict[str, Any]]:
    """The ego_pose records in table order, with the refined translation and rotation where there is one;
    records kept as logged are the records as read. `on_records(n)` as they are consumed."""
    for token, record in counted(table.items(), on_records):
        pose = entries[token].global_from_ego
        if pose is None:
            yield record
            continue
        refined = dict(record)
        refined["translation"] = [float(v) for v in pose.translation]
        refined["rotation"] = [float(v) for v in pose.rotation]
        yield refined


def write_ego_pose_json(
    out: Path,
    version_dir: Path,
    table: Table,
    entries: dict[str, EgoPoseEntry],
    *,
    on_records: Callable[[int], None] | None = None,
) -> None:
    """Write the source's ego_pose.json with refined translation and rotation to `out` (atomically, streamed):
    same records, order, fields and indentation as the source; records kept as logged come out as they were
    read. `on_records(n)` as records are encoded."""
    indent, newline = json_layout(table_path(version_dir, EGO_POSE))
    chunks = json_list_chunks(refined_records(table, entries, on_records), indent)
    atomic_write_chunks(out, itertools.chain(chunks, ["\n"] if newline else []))


def pose_sources_header(
    entries: dict[str, EgoPoseEntry], *, version: str, source_version: str, max_borrow_gap_us: int
) -> dict[str, Any]:
    """pose_sources.json without its `ego_poses`: the format, the versions, the rule and the counts per source."""
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
    }


def pose_source_record(entry: EgoPoseEntry) -> dict[str, Any]:
    """One ego_pose record's entry in pose_sources.json: its source, sample_data, channel, the camera image a
    non-camera record took its correction from, and whether the logged value was kept."""
    return {
        "source": entry.source,
        "sample_data": entry.sample_data,
        "channel": entry.channel,
        "correction_from": entry.correction_from,
        "logged": entry.global_from_ego is None,
    }


def pose_sources_chunks(
    header: dict[str, Any],
    entries: dict[str, EgoPoseEntry],
    *,
    batch: int = 4096,
    on_records: Callable[[int], None] | None = None,
) -> Iterator[str]:
    """The text of `json.dumps({**header, "ego_poses": {token: pose_source_record(entry)}}, indent=1)`, produced
    `batch` records at a time (2.6 million on nuScenes trainval); `on_records(n)` as they are encoded."""
    head = json.dumps(header, indent=1)
    yield head[:-2] + ',\n "ego_poses": {' if header else '{\n "ego_poses": {'
    started = False
    for chunk in chunked(counted(entries.items(), on_records), batch):
        records = {token: pose_source_record(entry) for token, entry in chunk}
        inner = json.dumps(records, indent=1)[2:-2].replace("\n", "\n ")  # one level deeper: one more space
        yield ("," if started else "") + "\n " + inner
        started = True
    yield "\n }\n}" if started else "}\n}"
