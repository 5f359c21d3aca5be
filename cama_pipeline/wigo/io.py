"""The WIGO stage's file, `wigo/<scene>.json` (`Workspace.wigo`): the only module that reads or writes it.

JSON, written atomically; times are int microseconds, positions global metres, quaternions [w, x, y, z],
poses global_from_ego.

    schema "cama.wigo/1": fused ego poses of one scene
        {"schema", "scene", "scene_token", "fingerprint", "config": {...}, "report": {...},
         "node_times_us": [int],
         "poses": [{"token": sample_data token, "channel", "timestamp_us",
                    "translation": [x, y, z], "rotation": [w, x, y, z],
                    "covariance": 36 floats (6x6 row-major, order rx ry rz tx ty tz in the ego frame,
                                  gtsam's tangent) or null}]}          one per camera image, time order
"""

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from cama_pipeline.io import WorkspaceError, atomic_write_json, field, read_json

WIGO_SCHEMA = "cama.wigo/1"


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
    for i, raw in enumerate(field(data, "poses", list, path)):
        where = f"poses[{i}]."
        if not isinstance(raw, dict):
            raise WorkspaceError(f"{path}: poses[{i}] must be an object")
        translation = np.asarray(field(raw, "translation", list, path, where), dtype=np.float64)
        rotation = np.asarray(field(raw, "rotation", list, path, where), dtype=np.float64)
        if translation.shape != (3,) or rotation.shape != (4,) or not np.all(np.isfinite(translation)):
            raise WorkspaceError(f"{path}: {where}translation/rotation must be 3 and 4 finite numbers")
        cov = raw.get("covariance")
        records.append(
            PoseRecord(
                token=field(raw, "token", str, path, where),
                channel=field(raw, "channel", str, path, where),
                timestamp_us=field(raw, "timestamp_us", int, path, where),
                translation=translation,
                rotation=rotation / np.linalg.norm(rotation),
                covariance=None if cov is None else np.asarray(cov, dtype=np.float64).reshape(6, 6),
            )
        )
    return WigoFile(
        scene=field(data, "scene", str, path),
        scene_token=field(data, "scene_token", str, path),
        fingerprint=field(data, "fingerprint", str, path),
        config=field(data, "config", dict, path),
        report=field(data, "report", dict, path),
        node_times_us=field(data, "node_times_us", list, path),
        poses=tuple(records),
    )
