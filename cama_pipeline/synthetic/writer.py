"""Writes a generated site as nuScenes tables (the layout documented in `cama_pipeline.data.schema`)."""

import datetime
import hashlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from cama_pipeline.data.schema import CAN_DIR, OPTIONAL_TABLES, REQUIRED_TABLES, can_file_name
from cama_pipeline.io import atomic_write_json
from cama_pipeline.synthetic.motion import matrix_to_quat
from cama_pipeline.synthetic.rig import RigCamera
from cama_pipeline.synthetic.schedule import CameraShot


def make_token(*parts: object) -> str:
    """A deterministic 32-hex-digit token (nuScenes tokens look like this) from the record's identity."""
    return hashlib.md5("/".join(str(p) for p in parts).encode()).hexdigest()


def image_filename(log_name: str, shot: CameraShot) -> str:
    """nuScenes-style relative image path: samples/ for key frames, sweeps/ otherwise."""
    folder = "samples" if shot.is_key_frame else "sweeps"
    return f"{folder}/{shot.channel}/{log_name}__{shot.channel}__{shot.timestamp_us}.jpg"


def _pose_record(token: str, timestamp_us: int, R: np.ndarray, t: np.ndarray) -> dict:
    return {
        "token": token,
        "timestamp": int(timestamp_us),
        "rotation": [float(q) for q in matrix_to_quat(R)],
        "translation": [float(v) for v in t],
    }


@dataclass
class NuScenesTables:
    """Accumulates the records of every table while clips are added, then writes them."""

    location: str
    tables: dict[str, list[dict]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for name in REQUIRED_TABLES + OPTIONAL_TABLES:
            self.tables.setdefault(name, [])

    def add_rig(self, rig: tuple[RigCamera, ...]) -> None:
        """One sensor and one calibrated_sensor record per camera (ego_from_cam, intrinsics)."""
        for cam in rig:
            self.tables["sensor"].append(
                {"token": make_token("sensor", cam.channel), "channel": cam.channel, "modality": "camera"}
            )
            self.tables["calibrated_sensor"].append(
                {
                    "token": make_token("calibrated_sensor", cam.channel),
                    "sensor_token": make_token("sensor", cam.channel),
                    "translation": [float(v) for v in cam.ego_from_cam_t],
                    "rotation": [float(q) for q in matrix_to_quat(cam.ego_from_cam_R)],
                    "camera_intrinsic": [[float(v) for v in row] for row in cam.K],
                }
            )

    def add_clip(
        self,
        scene_name: str,
        log_name: str,
        description: str,
        start_time_us: int,
        sample_times_us: tuple[int, ...],
        shots: tuple[CameraShot, ...],
        coarse_R: np.ndarray,
        coarse_t: np.ndarray,
        image_size: tuple[int, int],
    ) -> None:
        """Scene, log, samples, and one sample_data + ego_pose per shot (coarse poses, one row per shot)."""
        log_token = make_token("log", log_name)
        date = datetime.datetime.fromtimestamp(start_time_us / 1e6, tz=datetime.UTC).strftime("%Y-%m-%d")
        self.tables["log"].append(
            {
                "token": log_token,
                "logfile": log_name,
                "vehicle": "synth-zoe",
                "date_captured": date,
                "location": self.location,
            }
        )
        sample_tokens = [make_token(scene_name, "sample", k) for k in range(len(sample_times_us))]
        scene_token = make_token("scene", scene_name)
        for k, ts in enumerate(sample_times_us):
            self.tables["sample"].append(
                {
                    "token": sample_tokens[k],
                    "timestamp": int(ts),
                    "scene_token": scene_token,
                    "prev": sample_tokens[k - 1] if k > 0 else "",
                    "next": sample_tokens[k + 1] if k + 1 < len(sample_tokens) else "",
                }
            )
        self.tables["scene"].append(
            {
                "token": scene_token,
                "log_token": log_token,
                "nbr_samples": len(sample_tokens),
                "first_sample_token": sample_tokens[0],
                "last_sample_token": sample_tokens[-1],
                "name": scene_name,
                "description": description,
            }
        )
        self._add_sample_data(scene_name, log_name, sample_tokens, shots, coarse_R, coarse_t, image_size)

    def _add_sample_data(
        self,
        scene_name: str,
        log_name: str,
        sample_tokens: list[str],
        shots: tuple[CameraShot, ...],
        coarse_R: np.ndarray,
        coarse_t: np.ndarray,
        image_size: tuple[int, int],
    ) -> None:
        by_channel: dict[str, list[int]] = {}
        for i, shot in enumerate(shots):
            by_channel.setdefault(shot.channel, []).append(i)
        for channel, indices in by_channel.items():
            tokens = [make_token(scene_name, "sample_data", channel, shots[i].sweep_index) for i in indices]
            for pos, i in enumerate(indices):
                shot = shots[i]
                pose_token = make_token(scene_name, "ego_pose", channel, shot.sweep_index)
                self.tables["ego_pose"].append(
                    _pose_record(pose_token, shot.timestamp_us, coarse_R[i], coarse_t[i])
                )
                self.tables["sample_data"].append(
                    {
                        "token": tokens[pos],
                        "sample_token": sample_tokens[shot.sample_index],
                        "ego_pose_token": pose_token,
                        "calibrated_sensor_token": make_token("calibrated_sensor", channel),
                        "timestamp": shot.timestamp_us,
                        "fileformat": "jpg",
                        "is_key_frame": shot.is_key_frame,
                        "height": image_size[1],
                        "width": image_size[0],
                        "filename": image_filename(log_name, shot),
                        "prev": tokens[pos - 1] if pos > 0 else "",
                        "next": tokens[pos + 1] if pos + 1 < len(tokens) else "",
                    }
                )

    def add_map(self, filename: str) -> None:
        """The semantic prior (drivable area) image shared by all logs."""
        self.tables["map"].append(
            {
                "token": make_token("map", filename),
                "category": "semantic_prior",
                "filename": filename,
                "log_tokens": [r["token"] for r in self.tables["log"]],
            }
        )

    def write(self, version_dir: Path) -> None:
        """Write every table as `<version_dir>/<table>.json`."""
        for name, records in self.tables.items():
            atomic_write_json(version_dir / f"{name}.json", records, indent=None)


def write_can(root: Path, scene_name: str, messages: dict[str, list[dict]]) -> None:
    """Write one JSON list per CAN message of a scene into `<root>/can_bus/`."""
    for message, records in messages.items():
        atomic_write_json(root / CAN_DIR / can_file_name(scene_name, message), records)
