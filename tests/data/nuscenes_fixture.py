"""Writes tiny nuScenes-layout data sets by hand (1 scene, a few samples, 6 cameras), for loader tests."""

import json
import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from cama_pipeline.data.schema import (
    CAMERA_CHANNELS,
    CAN_DIR,
    GNSS_MESSAGE,
    IMU_MESSAGE,
    INSTANCE_DIR,
    OPTIONAL_TABLES,
    SEMANTIC_DIR,
    WHEEL_MESSAGE,
    can_file_name,
    mask_relpath,
)
from cama_pipeline.semantics import INSTANCE_ID_BASE, Semantic

T0_US = 1_532_402_927_000_000
SAMPLE_PERIOD_US = 500_000
CAMERA_STAGGER_US = 5_000
"""Each camera fires this much after the previous one, as nuScenes' rolling capture does."""
LIDAR_CHANNEL = "LIDAR_TOP"


@dataclass(frozen=True)
class NuScenesFixture:
    """Where a written fixture lies and what it holds, with helpers to break it for tests."""

    root: Path
    version: str
    scene_token: str
    scene_name: str
    sample_tokens: tuple[str, ...]
    """Samples in time order."""
    width: int
    height: int
    sweeps_per_sample: int

    @property
    def version_dir(self) -> Path:
        """Folder of the JSON tables."""
        return self.root / self.version

    def table_path(self, name: str) -> Path:
        """Path of one table file."""
        return self.version_dir / f"{name}.json"

    def read_table(self, name: str) -> list[dict[str, Any]]:
        """Records of one table, as written."""
        return json.loads(self.table_path(name).read_text())

    def write_table(self, name: str, records: list[dict[str, Any]]) -> None:
        """Replace one table's records."""
        _write_json(self.table_path(name), records)

    def edit_record(self, name: str, token: str, edit: Callable[[dict[str, Any]], None]) -> None:
        """Apply `edit` to the record `token` of table `name` in place on disk."""
        records = self.read_table(name)
        matches = [r for r in records if r["token"] == token]
        if len(matches) != 1:
            raise KeyError(f"{len(matches)} records with token {token!r} in {name}")
        edit(matches[0])
        self.write_table(name, records)

    def can_path(self, message: str) -> Path:
        """Path of one CAN message file of the scene."""
        return self.root / CAN_DIR / can_file_name(self.scene_name, message)


def sample_data_token(channel: str, sample_index: int, sweep_index: int = 0) -> str:
    """Token of a sample_data: sweep 0 is the key frame of the sample, 1.. the sweeps after it."""
    return f"sd-{channel}-{sample_index}-{sweep_index}"


def image_timestamp_us(
    channel_index: int, sample_index: int, sweep_index: int, sweeps_per_sample: int
) -> int:
    """Capture time of one image."""
    sample_time = T0_US + sample_index * SAMPLE_PERIOD_US
    return (
        sample_time
        + sweep_index * SAMPLE_PERIOD_US // (sweeps_per_sample + 1)
        + channel_index * CAMERA_STAGGER_US
    )


def ego_translation(timestamp_us: int) -> list[float]:
    """Ego position at a time: 5 m/s along x from (100, 200, 3)."""
    seconds = (timestamp_us - T0_US) / 1e6
    return [100.0 + 5.0 * seconds, 200.0, 3.0]


def ego_rotation(timestamp_us: int) -> list[float]:
    """Ego attitude at a time: yawing at 0.2 rad/s."""
    yaw = 0.2 * (timestamp_us - T0_US) / 1e6
    return [math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)]


def camera_translation(channel_index: int) -> list[float]:
    """ego_from_cam translation of camera `channel_index`."""
    return [1.5, 0.1 * channel_index, 1.6]


CAMERA_ROTATION = [0.5, -0.5, 0.5, -0.5]
"""ego_from_cam of a forward-looking camera: cam z (forward) -> ego x, cam x (right) -> ego -y."""


def camera_intrinsic(channel_index: int, width: int, height: int) -> list[list[float]]:
    """K of camera `channel_index`: focal length 10 + index pixels, principal point at the centre."""
    focal = 10.0 + channel_index
    return [[focal, 0.0, width / 2], [0.0, focal, height / 2], [0.0, 0.0, 1.0]]


def write_nuscenes_fixture(
    root: Path,
    *,
    version: str = "v1.0-fixture",
    n_samples: int = 3,
    sweeps_per_sample: int = 1,
    width: int = 16,
    height: int = 8,
    with_masks: bool = True,
    with_can: bool = True,
    with_gnss: bool = True,
    with_lidar: bool = True,
    with_optional_tables: bool = True,
) -> NuScenesFixture:
    """Write a one-scene data set under `root`: tables, tiny JPEGs (and masks), CAN files."""
    fixture = NuScenesFixture(
        root=Path(root),
        version=version,
        scene_token="scene-token-1",
        scene_name="scene-0001",
        sample_tokens=tuple(f"sample-{i}" for i in range(n_samples)),
        width=width,
        height=height,
        sweeps_per_sample=sweeps_per_sample,
    )
    tables = _base_tables(fixture, with_lidar)
    _add_sample_data(fixture, tables, with_masks)
    if with_lidar:
        _add_lidar_data(fixture, tables)
    for name, records in tables.items():
        fixture.write_table(name, records)
    if with_optional_tables:
        for name in OPTIONAL_TABLES:
            fixture.write_table(name, [])
    if with_can:
        _write_can(fixture, with_gnss)
    return fixture


def _base_tables(fixture: NuScenesFixture, with_lidar: bool) -> dict[str, list[dict[str, Any]]]:
    """scene, sample, log, sensor and calibrated_sensor tables; sample_data and ego_pose left empty."""
    samples = fixture.sample_tokens
    sample_records = [
        {
            "token": token,
            "timestamp": T0_US + i * SAMPLE_PERIOD_US,
            "prev": samples[i - 1] if i > 0 else "",
            "next": samples[i + 1] if i + 1 < len(samples) else "",
            "scene_token": fixture.scene_token,
        }
        for i, token in enumerate(samples)
    ]
    scene = {
        "token": fixture.scene_token,
        "log_token": "log-1",
        "nbr_samples": len(samples),
        "first_sample_token": samples[0],
        "last_sample_token": samples[-1],
        "name": fixture.scene_name,
        "description": "fixture scene, day",
    }
    log = {
        "token": "log-1",
        "logfile": "fixture-log",
        "vehicle": "fixture-car",
        "date_captured": "2018-07-24",
        "location": "fixture-town",
    }
    sensors = [{"token": f"sensor-{ch}", "channel": ch, "modality": "camera"} for ch in CAMERA_CHANNELS]
    calibrations = [
        {
            "token": f"cs-{ch}",
            "sensor_token": f"sensor-{ch}",
            "translation": camera_translation(j),
            "rotation": CAMERA_ROTATION,
            "camera_intrinsic": camera_intrinsic(j, fixture.width, fixture.height),
        }
        for j, ch in enumerate(CAMERA_CHANNELS)
    ]
    if with_lidar:
        sensors.append({"token": f"sensor-{LIDAR_CHANNEL}", "channel": LIDAR_CHANNEL, "modality": "lidar"})
        calibrations.append(
            {
                "token": f"cs-{LIDAR_CHANNEL}",
                "sensor_token": f"sensor-{LIDAR_CHANNEL}",
                "translation": [0.9, 0.0, 1.8],
                "rotation": [1.0, 0.0, 0.0, 0.0],
                "camera_intrinsic": [],
            }
        )
    return {
        "scene": [scene],
        "sample": sample_records,
        "log": [log],
        "sensor": sensors,
        "calibrated_sensor": calibrations,
        "sample_data": [],
        "ego_pose": [],
    }


def _add_sample_data(
    fixture: NuScenesFixture, tables: dict[str, list[dict[str, Any]]], with_masks: bool
) -> None:
    """Camera sample_data (key frames and sweeps, prev/next chained per channel), ego poses, image files."""
    n_sweeps = fixture.sweeps_per_sample
    for j, channel in enumerate(CAMERA_CHANNELS):
        chain = [(i, k) for i in range(len(fixture.sample_tokens)) for k in range(n_sweeps + 1)]
        tokens = [sample_data_token(channel, i, k) for i, k in chain]
        for n, (i, k) in enumerate(chain):
            timestamp = image_timestamp_us(j, i, k, n_sweeps)
            folder = "samples" if k == 0 else "sweeps"
            filename = f"{folder}/{channel}/fixture__{channel}__{timestamp}.jpg"
            tables["ego_pose"].append(
                {
                    "token": f"ep-{tokens[n]}",
                    "timestamp": timestamp,
                    "translation": ego_translation(timestamp),
                    "rotation": ego_rotation(timestamp),
                }
            )
            tables["sample_data"].append(
                {
                    "token": tokens[n],
                    "sample_token": fixture.sample_tokens[i],
                    "ego_pose_token": f"ep-{tokens[n]}",
                    "calibrated_sensor_token": f"cs-{channel}",
                    "timestamp": timestamp,
                    "fileformat": "jpg",
                    "is_key_frame": k == 0,
                    "height": fixture.height,
                    "width": fixture.width,
                    "filename": filename,
                    "prev": tokens[n - 1] if n > 0 else "",
                    "next": tokens[n + 1] if n + 1 < len(tokens) else "",
                }
            )
            _write_image_files(fixture, filename, j, with_masks)


def _write_image_files(fixture: NuScenesFixture, filename: str, channel_index: int, with_masks: bool) -> None:
    """A solid-colour JPEG (red = 10 * channel index) and, if asked, its semantic and instance masks."""
    bgr = np.zeros((fixture.height, fixture.width, 3), np.uint8)
    bgr[:, :, 2] = 10 * channel_index
    bgr[:, :, 1] = 200
    _imwrite(fixture.root / filename, bgr)
    if with_masks:
        semantic = np.full((fixture.height, fixture.width), int(Semantic.ROAD), np.uint8)
        semantic[0, :] = Semantic.SKY
        instance = np.zeros((fixture.height, fixture.width), np.uint16)
        instance[-1, :] = Semantic.LANE_MARKING * INSTANCE_ID_BASE + 1
        _imwrite(fixture.root / mask_relpath(SEMANTIC_DIR, filename), semantic)
        _imwrite(fixture.root / mask_relpath(INSTANCE_DIR, filename), instance)


def _add_lidar_data(fixture: NuScenesFixture, tables: dict[str, list[dict[str, Any]]]) -> None:
    """One lidar key frame per sample, with no file on disk: the loader must ignore non-camera data."""
    for i, sample in enumerate(fixture.sample_tokens):
        token = sample_data_token(LIDAR_CHANNEL, i)
        timestamp = T0_US + i * SAMPLE_PERIOD_US
        tables["ego_pose"].append(
            {
                "token": f"ep-{token}",
                "timestamp": timestamp,
                "translation": ego_translation(timestamp),
                "rotation": ego_rotation(timestamp),
            }
        )
        tables["sample_data"].append(
            {
                "token": token,
                "sample_token": sample,
                "ego_pose_token": f"ep-{token}",
                "calibrated_sensor_token": f"cs-{LIDAR_CHANNEL}",
                "timestamp": timestamp,
                "fileformat": "pcd",
                "is_key_frame": True,
                "height": 0,
                "width": 0,
                "filename": f"samples/{LIDAR_CHANNEL}/fixture__{LIDAR_CHANNEL}__{timestamp}.pcd.bin",
                "prev": sample_data_token(LIDAR_CHANNEL, i - 1) if i > 0 else "",
                "next": sample_data_token(LIDAR_CHANNEL, i + 1) if i + 1 < len(fixture.sample_tokens) else "",
            }
        )


N_IMU = 20
N_WHEEL = 10
N_GNSS = 4


def _write_can(fixture: NuScenesFixture, with_gnss: bool) -> None:
    """IMU (100 Hz), wheel (50 Hz) and, if asked, GNSS (1 Hz) message files of the scene."""
    imu = [
        {
            "utime": T0_US + 10_000 * n,
            "linear_accel": [0.1 * n, 0.0, 9.81],
            "rotation_rate": [0.0, 0.0, 0.2],
            "q": [1.0, 0.0, 0.0, 0.0],
            "extra_field": 1,
        }
        for n in range(N_IMU)
    ]
    wheel = [
        {
            "utime": T0_US + 20_000 * n,
            "FL_wheel_speed": 150.0 + n,
            "FR_wheel_speed": 151.0 + n,
            "RL_wheel_speed": 152.0 + n,
            "RR_wheel_speed": 153.0 + n,
        }
        for n in range(N_WHEEL)
    ]
    _write_json(fixture.can_path(IMU_MESSAGE), imu)
    _write_json(fixture.can_path(WHEEL_MESSAGE), wheel)
    if with_gnss:
        gnss = [
            {
                "utime": T0_US + 1_000_000 * n,
                "pos": ego_translation(T0_US + 1_000_000 * n),
                "std_m": [0.5, 0.5, 1.0],
                "fix": n != 2,
            }
            for n in range(N_GNSS)
        ]
        _write_json(fixture.can_path(GNSS_MESSAGE), gnss)


def _write_json(path: Path, obj: Any) -> None:
    """Write JSON with one field a line, so that syntax errors have meaningful line numbers."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(obj, indent=2))


def _imwrite(path: Path, image: np.ndarray) -> None:
    """cv2.imwrite into a fresh folder, failing loudly."""
    path.parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(path), image):
        raise OSError(f"could not write {path}")
