"""The site workspace on disk: what `cama wigo`, `cama keyframes` and `cama sites` write, and how later
stages (pairs, SfM) read it. This module is the only one that reads or writes these files.

Default location: `<data set root's parent>/workspace/` (for `data/synthetic/default/nuscenes` that is
`data/synthetic/default/workspace/`). All files are JSON, written atomically; times are int microseconds,
positions global metres, quaternions [w, x, y, z], poses global_from_ego.

    wigo/<scene>.json          schema "cama.wigo/1": fused ego poses of one scene
        {"schema", "scene", "scene_token", "fingerprint", "config": {...}, "report": {...},
         "node_times_us": [int],
         "poses": [{"token": sample_data token, "channel", "timestamp_us",
                    "translation": [x, y, z], "rotation": [w, x, y, z],
                    "covariance": 36 floats (6x6 row-major, order rx ry rz tx ty tz in the ego frame,
                                  gtsam's tangent) or null}]}          one per camera image, time order
    keyframes/<scene>.json     schema "cama.keyframes/1": resynchronised frames and keyframes
        {"schema", "scene", "fingerprint", "config": {...}, "stationary": bool, "path_length_m",
         "max_time_diff_us": largest |image time - frame time| over all frames,
         "max_time_range_us": largest (latest - earliest image time) within a frame,
         "frames": [{"index", "timestamp_us": the reference camera's time,
                     "images": {channel: sample_data token}, "time_diff_us", "keyframe": bool,
                     "reason": "first" | "translation" | "rotation" | "last" | "stationary" | ""}]}
    sites/index.json           schema "cama.sites/1": the aggregation's decisions
        {"schema", "fingerprint", "config": {...},
         "sites": [{"site_id", "scenes": [scene], "merged": {stationary scene: moving scene}}],
         "dropped": [{"scene", "reason"}]}
    sites/<site_id>/manifest.json   schema "cama.site/1": everything a site's reconstruction reads
        {"schema", "site_id", "scenes": [{"scene", "scene_token", "kind": "moving" | "stationary",
                                          "merged_into": scene or null, "frames": [frame as above]}],
         "poses": {sample_data token: {"scene", "channel", "timestamp_us", "translation", "rotation"}}}
"""

import hashlib
import json
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from cama_pipeline.io import atomic_write_json

WIGO_SCHEMA = "cama.wigo/1"
KEYFRAMES_SCHEMA = "cama.keyframes/1"
SITES_SCHEMA = "cama.sites/1"
SITE_SCHEMA = "cama.site/1"
WORKSPACE_DIRNAME = "workspace"


class WorkspaceError(ValueError):
    """A workspace file that is missing a stage's output or breaks its schema; names file and field."""


def default_workspace(dataset_root: Path) -> Path:
    """`<dataset_root's parent>/workspace`: beside the data set, never inside it."""
    return Path(dataset_root).absolute().parent / WORKSPACE_DIRNAME


def wigo_path(workspace: Path, scene: str) -> Path:
    return Path(workspace) / "wigo" / f"{scene}.json"


def keyframes_path(workspace: Path, scene: str) -> Path:
    return Path(workspace) / "keyframes" / f"{scene}.json"


def sites_index_path(workspace: Path) -> Path:
    return Path(workspace) / "sites" / "index.json"


def site_manifest_path(workspace: Path, site_id: str) -> Path:
    return Path(workspace) / "sites" / site_id / "manifest.json"


def fingerprint(*parts: Any) -> str:
    """A short stable hash of JSON-able parts (configs, input stats, upstream fingerprints)."""
    text = json.dumps(parts, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def file_stats(paths: list[Path]) -> list[tuple[str, int, int]]:
    """(name, size, mtime_ns) of each existing file, for fingerprints of inputs."""
    return [(p.name, p.stat().st_size, p.stat().st_mtime_ns) for p in paths if p.is_file()]


# -- reading helpers ----------------------------------------------------------------------------------------


def read_json(path: Path, schema: str, stage_hint: str) -> dict[str, Any]:
    """A workspace JSON object of `schema`; FileNotFoundError says which command writes it."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: not found; run `{stage_hint}` first")
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as err:
        raise WorkspaceError(f"{path}: not valid JSON ({err})") from None
    if not isinstance(data, dict) or data.get("schema") != schema:
        found = data.get("schema") if isinstance(data, dict) else type(data).__name__
        raise WorkspaceError(f"{path}: field 'schema' must be {schema!r}, got {found!r}")
    return data


def _field(
    data: Mapping[str, Any], name: str, kind: type | tuple[type, ...], path: Path, where: str = ""
) -> Any:
    """data[name] checked to be of `kind`, else a WorkspaceError naming the file and field."""
    if name not in data or not isinstance(data[name], kind) or isinstance(data[name], bool) and kind is int:
        raise WorkspaceError(f"{path}: field {where}{name!r} missing or not {kind}")
    return data[name]


# -- WIGO poses ---------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class PoseRecord:
    """One fused ego pose at a camera image."""

    token: str
    channel: str
    timestamp_us: int
    translation: np.ndarray
    """(3,) global metres."""
    rotation: np.ndarray
    """(4,) [w, x, y, z]."""
    covariance: np.ndarray | None
    """(6, 6) in gtsam's tangent order, or None."""


@dataclass(frozen=True, eq=False)
class WigoFile:
    """Contents of `wigo/<scene>.json`."""

    scene: str
    scene_token: str
    fingerprint: str
    config: dict[str, Any]
    report: dict[str, Any]
    node_times_us: list[int]
    poses: tuple[PoseRecord, ...]


def write_wigo(path: Path, wigo: WigoFile) -> None:
    """Write a WIGO pose file atomically."""
    poses = [
        {
            "token": p.token,
            "channel": p.channel,
            "timestamp_us": int(p.timestamp_us),
            "translation": [float(v) for v in p.translation],
            "rotation": [float(v) for v in p.rotation],
            "covariance": None
            if p.covariance is None or not np.all(np.isfinite(p.covariance))
            else [float(v) for v in np.ravel(p.covariance)],
        }
        for p in wigo.poses
    ]
    atomic_write_json(
        path,
        {
            "schema": WIGO_SCHEMA,
            "scene": wigo.scene,
            "scene_token": wigo.scene_token,
            "fingerprint": wigo.fingerprint,
            "config": wigo.config,
            "report": wigo.report,
            "node_times_us": [int(t) for t in wigo.node_times_us],
            "poses": poses,
        },
    )


def read_wigo(path: Path) -> WigoFile:
    """Read and check a WIGO pose file."""
    data = read_json(path, WIGO_SCHEMA, "cama wigo")
    records = []
    for i, raw in enumerate(_field(data, "poses", list, path)):
        where = f"poses[{i}]."
        if not isinstance(raw, dict):
            raise WorkspaceError(f"{path}: poses[{i}] must be an object")
        translation = np.asarray(_field(raw, "translation", list, path, where), dtype=np.float64)
        rotation = np.asarray(_field(raw, "rotation", list, path, where), dtype=np.float64)
        if translation.shape != (3,) or rotation.shape != (4,) or not np.all(np.isfinite(translation)):
            raise WorkspaceError(f"{path}: {where}translation/rotation must be 3 and 4 finite numbers")
        cov = raw.get("covariance")
        records.append(
            PoseRecord(
                token=_field(raw, "token", str, path, where),
                channel=_field(raw, "channel", str, path, where),
                timestamp_us=_field(raw, "timestamp_us", int, path, where),
                translation=translation,
                rotation=rotation / np.linalg.norm(rotation),
                covariance=None if cov is None else np.asarray(cov, dtype=np.float64).reshape(6, 6),
            )
        )
    return WigoFile(
        scene=_field(data, "scene", str, path),
        scene_token=_field(data, "scene_token", str, path),
        fingerprint=_field(data, "fingerprint", str, path),
        config=_field(data, "config", dict, path),
        report=_field(data, "report", dict, path),
        node_times_us=_field(data, "node_times_us", list, path),
        poses=tuple(records),
    )


def stored_fingerprint(path: Path) -> str | None:
    """The `fingerprint` of an existing workspace file, None when absent or unreadable."""
    try:
        value = json.loads(Path(path).read_text(encoding="utf-8")).get("fingerprint")
    except (OSError, ValueError, AttributeError):
        return None
    return value if isinstance(value, str) else None


# -- keyframes ----------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class FrameRecord:
    """One resynchronised multi-camera frame."""

    index: int
    timestamp_us: int
    """The reference camera's capture time (the frame's time)."""
    images: dict[str, str]
    """channel -> sample_data token."""
    time_diff_us: int
    """Largest |image time - frame time| in this frame."""
    keyframe: bool
    reason: str
    """Why it is a keyframe: first, translation, rotation, last, stationary (empty when not)."""

    def to_json(self) -> dict[str, Any]:
        return {
            "index": self.index,
            "timestamp_us": self.timestamp_us,
            "images": dict(self.images),
            "time_diff_us": self.time_diff_us,
            "keyframe": self.keyframe,
            "reason": self.reason,
        }


@dataclass(frozen=True, eq=False)
class KeyframesFile:
    """Contents of `keyframes/<scene>.json`."""

    scene: str
    fingerprint: str
    config: dict[str, Any]
    stationary: bool
    path_length_m: float
    max_time_diff_us: int
    max_time_range_us: int
    frames: tuple[FrameRecord, ...]

    @property
    def keyframes(self) -> tuple[FrameRecord, ...]:
        return tuple(f for f in self.frames if f.keyframe)


def write_keyframes(path: Path, data: KeyframesFile) -> None:
    """Write a keyframes file atomically."""
    atomic_write_json(
        path,
        {
            "schema": KEYFRAMES_SCHEMA,
            "scene": data.scene,
            "fingerprint": data.fingerprint,
            "config": data.config,
            "stationary": data.stationary,
            "path_length_m": data.path_length_m,
            "max_time_diff_us": data.max_time_diff_us,
            "max_time_range_us": data.max_time_range_us,
            "frames": [f.to_json() for f in data.frames],
        },
    )


def _frame(raw: Any, path: Path, i: int) -> FrameRecord:
    where = f"frames[{i}]."
    if not isinstance(raw, dict):
        raise WorkspaceError(f"{path}: frames[{i}] must be an object")
    images = _field(raw, "images", dict, path, where)
    if not all(isinstance(k, str) and isinstance(v, str) for k, v in images.items()):
        raise WorkspaceError(f"{path}: {where}images must map channel names to tokens")
    return FrameRecord(
        index=_field(raw, "index", int, path, where),
        timestamp_us=_field(raw, "timestamp_us", int, path, where),
        images=images,
        time_diff_us=_field(raw, "time_diff_us", int, path, where),
        keyframe=_field(raw, "keyframe", bool, path, where),
        reason=_field(raw, "reason", str, path, where),
    )


def read_keyframes(path: Path) -> KeyframesFile:
    """Read and check a keyframes file."""
    data = read_json(path, KEYFRAMES_SCHEMA, "cama keyframes")
    frames = tuple(_frame(raw, path, i) for i, raw in enumerate(_field(data, "frames", list, path)))
    return KeyframesFile(
        scene=_field(data, "scene", str, path),
        fingerprint=_field(data, "fingerprint", str, path),
        config=_field(data, "config", dict, path),
        stationary=_field(data, "stationary", bool, path),
        path_length_m=float(_field(data, "path_length_m", (int, float), path)),
        max_time_diff_us=_field(data, "max_time_diff_us", int, path),
        max_time_range_us=_field(data, "max_time_range_us", int, path),
        frames=frames,
    )


# -- sites --------------------------------------------------------------------------------------------------


def write_sites_index(path: Path, index: dict[str, Any]) -> None:
    """Write `sites/index.json` (built by `cama_pipeline.site.aggregate`) atomically."""
    atomic_write_json(path, {"schema": SITES_SCHEMA, **index}, indent=1)


def read_sites_index(path: Path) -> dict[str, Any]:
    """Read `sites/index.json`; checks the schema and that `sites` and `dropped` are lists."""
    data = read_json(path, SITES_SCHEMA, "cama sites")
    _field(data, "sites", list, path)
    _field(data, "dropped", list, path)
    return data


def write_site_manifest(path: Path, manifest: dict[str, Any]) -> None:
    """Write one site's `manifest.json` atomically."""
    atomic_write_json(path, {"schema": SITE_SCHEMA, **manifest})


def read_site_manifest(path: Path) -> dict[str, Any]:
    """Read a site manifest; checks the schema and the `scenes` and `poses` fields."""
    data = read_json(path, SITE_SCHEMA, "cama sites")
    _field(data, "scenes", list, path)
    _field(data, "poses", dict, path)
    return data
