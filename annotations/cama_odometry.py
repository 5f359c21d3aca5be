"""The odometry of a release scene: per camera, `odometry/<mode>_camera_<cam>.txt` with one TUM row per image of
that scene only, `t x y z qx qy qz qw` (camera to world, world = the map's frame, `annotations.cama_frame`), t in
seconds with exactly three decimals (millisecond digits), no header line; rows in time order.

`pose_sources.json` beside them (our extension): per odometry file the count of rows per pose source and each
row's source (`annotations.poses`), in row order.
"""

import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from annotations.cama_frame import ReleaseFrame
from annotations.poses import POSE_SOURCES, PoseLookup, PoseSource
from cama_pipeline.data import CameraImage, Pose, Scene
from cama_pipeline.io import atomic_write_bytes

CAMERA_NAME_FROM_CHANNEL: dict[str, str] = {
    "CAM_FRONT": "camera_front",
    "CAM_FRONT_LEFT": "camera_front_left",
    "CAM_FRONT_RIGHT": "camera_front_right",
    "CAM_BACK": "camera_rear",
    "CAM_BACK_LEFT": "camera_rear_left",
    "CAM_BACK_RIGHT": "camera_rear_right",
}
"""nuScenes camera channel -> CAMA camera name (the one table; CAM_BACK* is camera_rear*)."""
POSE_SOURCES_FILE = "pose_sources.json"


@dataclass(frozen=True, eq=False)
class CameraPose:
    """One image of a scene with its camera-to-global pose (from the export's lookup) and that pose's source."""

    image: CameraImage
    global_from_cam: Pose
    source: PoseSource


def camera_name(channel: str, *, scene: str) -> str:
    """The CAMA camera name of a channel; ValueError naming the channel, scene and the known channels."""
    try:
        return CAMERA_NAME_FROM_CHANNEL[channel]
    except KeyError:
        known = sorted(CAMERA_NAME_FROM_CHANNEL)
        raise ValueError(
            f"scene {scene}: camera channel {channel!r} has no CAMA camera name; known: {known}"
        ) from None


def timestamp_ms(timestamp_us: int) -> int:
    """A microsecond timestamp rounded to whole milliseconds (half up)."""
    return (int(timestamp_us) + 500) // 1000


def tum_time(timestamp_us: int) -> str:
    """Seconds with exactly three decimals, from whole milliseconds (no float rounding)."""
    ms = timestamp_ms(timestamp_us)
    return f"{ms // 1000}.{ms % 1000:03d}"


def scene_camera_poses(scene: Scene, poses: PoseLookup) -> list[CameraPose]:
    """Every camera image of the scene (time order) with its camera-to-global pose; ValueError for a channel
    without a CAMA name or a scene without images."""
    images = scene.all_images()
    if not images:
        raise ValueError(f"scene {scene.name}: no camera images")
    out = []
    for image in images:
        camera_name(image.channel, scene=scene.name)
        sourced = poses(image)
        out.append(
            CameraPose(image, sourced.global_from_ego @ image.calibration.ego_from_cam, sourced.source)
        )
    return out


def tum_row(camera: CameraPose, frame: ReleaseFrame) -> str:
    """`t x y z qx qy qz qw` of one image: camera to world (the frame's translation only; axes unchanged)."""
    x, y, z = frame.world_from_global(camera.global_from_cam.translation)
    qw, qx, qy, qz = np.asarray(camera.global_from_cam.rotation, dtype=float)
    return (
        f"{tum_time(camera.image.timestamp_us)} {x:.6f} {y:.6f} {z:.6f} {qx:.9f} {qy:.9f} {qz:.9f} {qw:.9f}"
    )


def write_odometry(
    cameras: Sequence[CameraPose], folder: Path, *, prefix: str, frame: ReleaseFrame
) -> dict[str, int]:
    """One file per camera in `folder` plus `pose_sources.json`; returns the rows written per file name."""
    rows: dict[str, list[tuple[int, str, PoseSource]]] = {}
    for camera in cameras:
        name = f"{prefix}_{camera_name(camera.image.channel, scene=folder.parent.name)}.txt"
        rows.setdefault(name, []).append((camera.image.timestamp_us, tum_row(camera, frame), camera.source))
    sources: dict[str, object] = {}
    for name, lines in sorted(rows.items()):
        ordered = sorted(lines, key=lambda row: row[:2])
        atomic_write_bytes(folder / name, "".join(line + "\n" for _, line, _ in ordered).encode("utf-8"))
        row_sources = [source for _, _, source in ordered]
        sources[name] = {
            "counts": {s: row_sources.count(s) for s in POSE_SOURCES if s in row_sources},
            "rows": row_sources,
        }
    atomic_write_bytes(folder / POSE_SOURCES_FILE, json.dumps(sources, indent=1).encode("utf-8"))
    return {name: len(lines) for name, lines in rows.items()}
