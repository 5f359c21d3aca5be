"""The keyframes stage's file, `keyframes/<scene>.json` (`Workspace.keyframes`): the only module that reads or
writes it.

JSON, written atomically; times are int microseconds.

    schema "cama.keyframes/1": resynchronised frames and keyframes
        {"schema", "scene", "fingerprint", "config": {...}, "stationary": bool, "path_length_m",
         "max_time_diff_us": largest |image time - frame time| over all frames,
         "max_time_range_us": largest (latest - earliest image time) within a frame,
         "frames": [{"index", "timestamp_us": the reference camera's time,
                     "images": {channel: sample_data token}, "time_diff_us", "keyframe": bool,
                     "reason": "first" | "translation" | "rotation" | "last" | "stationary" | ""}]}
"""

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from cama_pipeline.io import WorkspaceError, atomic_write_json, field, read_json

KEYFRAMES_SCHEMA = "cama.keyframes/1"


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
    images = field(raw, "images", dict, path, where)
    if not all(isinstance(k, str) and isinstance(v, str) for k, v in images.items()):
        raise WorkspaceError(f"{path}: {where}images must map channel names to tokens")
    return FrameRecord(
        index=field(raw, "index", int, path, where),
        timestamp_us=field(raw, "timestamp_us", int, path, where),
        images=images,
        time_diff_us=field(raw, "time_diff_us", int, path, where),
        keyframe=field(raw, "keyframe", bool, path, where),
        reason=field(raw, "reason", str, path, where),
    )


def read_keyframes(path: Path) -> KeyframesFile:
    """Read and check a keyframes file."""
    data = read_json(path, KEYFRAMES_SCHEMA, "cama keyframes")
    frames = tuple(_frame(raw, path, i) for i, raw in enumerate(field(data, "frames", list, path)))
    return KeyframesFile(
        scene=field(data, "scene", str, path),
        fingerprint=field(data, "fingerprint", str, path),
        config=field(data, "config", dict, path),
        stationary=field(data, "stationary", bool, path),
        path_length_m=float(field(data, "path_length_m", (int, float), path)),
        max_time_diff_us=field(data, "max_time_diff_us", int, path),
        max_time_range_us=field(data, "max_time_range_us", int, path),
        frames=frames,
    )
