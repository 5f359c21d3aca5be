"""`attribute.json` of CAMA clip data: the synchronised image timestamps and the cameras' calibration.

What CAMA's code reads (public CAMA code, found with the code search; its `DatasetReader`, `CameraManager`,
`ClipManager` and its nuScenes converter `nuScenes2Clip`, which writes this file for nuScenes scenes):

    attribute["sync"][<camera>][index]           integer milliseconds; image `<camera>/<ms>.jpg` and mask
                                                 `lane_ins_<camera>/<ms>.png`; every list index-aligned with
                                                 `camera_front` (the metric loops over the indices of
                                                 `camera_main`, skipping index 0, and reads every camera's
                                                 image and mask at the same index; a missing mask file fails it)
    attribute["calibration"]["<camera>_2_chassis"]   4x4, maps camera points into the chassis (ego) frame;
                                                 `get_extrinsic("chassis", camera)` inverts it
    attribute["calibration"][<camera>]           {"K": 3x3, "d": distortion (OpenCV order; the converter
                                                 writes 8 zeros for nuScenes' pinhole cameras),
                                                 "image_width", "image_height", "fov"}; the converter also
                                                 writes "center_u", "center_v", "focal_u", "focal_v", "distort"
    attribute["start_time"], ["end_time"]        milliseconds of the scene's first and last sample

Sync rule (the converter's `get_sync_info`, reference `camera_front`, tolerance 40 ms): for each camera_front
image in time order, each other camera's nearest image in time (the earlier one on a tie); when a camera has
no image within the tolerance the whole camera_front frame is dropped from every list (CAMA's lists must stay
the same length), and we record the dropped frame and the cameras that had none in our sidecar. We compare
microsecond times (the converter compares rounded milliseconds). Milliseconds are the microsecond time rounded
half up (`annotations.cama_odometry.timestamp_ms`, the same as the odometry's t).

Not written: `unsync` (every image of every sensor; CAMA's metric reads only `sync`, and only the synchronised
images are exported), `status`, and the lidar's calibration (our data sets have no lidar).
"""

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from annotations.cama_odometry import CAMERA_NAME_FROM_CHANNEL, camera_name, timestamp_ms
from cama_pipeline.data import CameraImage, Scene

REFERENCE_CAMERA = "camera_front"
"""The camera every sync list is aligned with."""
DEFAULT_MAX_SYNC_DIFF_MS = 40
"""CAMA's converter's tolerance between a camera_front image and another camera's image."""
DISTORTION_LENGTH = 8
"""Length of `d`: the converter's 8 zeros (OpenCV's rational model length) for pinhole cameras."""
CHASSIS = "chassis"
"""CAMA's name of the vehicle frame; ours is the ego frame (`CameraCalibration.ego_from_cam`)."""


@dataclass(frozen=True)
class DroppedFrame:
    """A camera_front image left out of the sync lists: some camera had no image within the tolerance."""

    timestamp_ms: int
    """The camera_front image's time."""
    cameras_without_image: tuple[str, ...]
    """The cameras (CAMA names) with no image within the tolerance."""


@dataclass(frozen=True, eq=False)
class ClipSync:
    """The synchronised images of one scene."""

    cameras: tuple[str, ...]
    """CAMA camera names, camera_front first, then in `CAMERA_NAME_FROM_CHANNEL` order."""
    rows: tuple[dict[str, CameraImage], ...]
    """Per kept camera_front image (time order): the image of every camera."""
    dropped: tuple[DroppedFrame, ...]
    """camera_front images left out."""

    def timestamps_ms(self) -> dict[str, list[int]]:
        """`attribute["sync"]`: per camera its images' milliseconds, index-aligned with camera_front."""
        return {name: [timestamp_ms(row[name].timestamp_us) for row in self.rows] for name in self.cameras}

    def images(self) -> dict[str, list[CameraImage]]:
        """Per camera the distinct images the sync lists name, in time order."""
        out: dict[str, list[CameraImage]] = {}
        for name in self.cameras:
            seen: dict[str, CameraImage] = {row[name].token: row[name] for row in self.rows}
            out[name] = sorted(seen.values(), key=lambda im: im.timestamp_us)
        return out


def images_by_camera(scene: Scene) -> dict[str, tuple[CameraImage, ...]]:
    """The scene's images per CAMA camera name (camera_front first); ValueError for a channel without a CAMA
    name or a scene without camera_front images."""
    named = {
        camera_name(channel, scene=scene.name): images for channel, images in scene.images.items() if images
    }
    if REFERENCE_CAMERA not in named:
        raise ValueError(
            f"scene {scene.name}: no CAM_FRONT images; CAMA's sync lists are aligned with {REFERENCE_CAMERA}"
        )
    order = [REFERENCE_CAMERA] + [
        n for n in CAMERA_NAME_FROM_CHANNEL.values() if n in named and n != REFERENCE_CAMERA
    ]
    return {name: tuple(sorted(named[name], key=lambda im: im.timestamp_us)) for name in order}


def sync_scene(scene: Scene, *, max_diff_ms: float = DEFAULT_MAX_SYNC_DIFF_MS) -> ClipSync:
    """The sync rows of a scene (the module docstring's rule); ValueError when `max_diff_ms` is negative or
    not finite, or when two images of one camera round to the same millisecond (they would share a file)."""
    if not (math.isfinite(max_diff_ms) and max_diff_ms >= 0):
        raise ValueError(f"max_sync_diff_ms: expected a finite value >= 0, got {max_diff_ms}")
    by_camera = images_by_camera(scene)
    for name, images in by_camera.items():
        _check_distinct_ms(scene.name, name, images)
    times = {
        name: np.array([im.timestamp_us for im in images], dtype=np.int64)
        for name, images in by_camera.items()
    }
    rows: list[dict[str, CameraImage]] = []
    dropped: list[DroppedFrame] = []
    for reference in by_camera[REFERENCE_CAMERA]:
        row = {REFERENCE_CAMERA: reference}
        missing = []
        for name, images in by_camera.items():
            if name == REFERENCE_CAMERA:
                continue
            gaps = np.abs(times[name] - reference.timestamp_us)
            nearest = int(np.argmin(gaps))
            if gaps[nearest] <= max_diff_ms * 1000:
                row[name] = images[nearest]
            else:
                missing.append(name)
        if missing:
            dropped.append(DroppedFrame(timestamp_ms(reference.timestamp_us), tuple(missing)))
        else:
            rows.append(row)
    return ClipSync(tuple(by_camera), tuple(rows), tuple(dropped))


def _check_distinct_ms(scene: str, camera: str, images: Sequence[CameraImage]) -> None:
    """ValueError naming both images when two of one camera fall on the same millisecond."""
    seen: dict[int, CameraImage] = {}
    for image in images:
        ms = timestamp_ms(image.timestamp_us)
        if ms in seen:
            raise ValueError(
                f"scene {scene}: {camera} images {seen[ms].path.name} and {image.path.name} both round to "
                f"{ms} ms, so both would be written as {camera}/{ms}.jpg"
            )
        seen[ms] = image


def camera_calibration(scene: str, camera: str, images: Sequence[CameraImage]) -> dict[str, Any]:
    """`calibration[camera]` of the images a camera's sync list names; ValueError when they do not share one
    calibration (attribute.json holds one per camera)."""
    first = images[0].calibration
    for image in images[1:]:
        other = image.calibration
        same = (
            other.width == first.width
            and other.height == first.height
            and np.array_equal(other.intrinsic, first.intrinsic)
            and np.array_equal(other.ego_from_cam.matrix(), first.ego_from_cam.matrix())
        )
        if not same:
            raise ValueError(
                f"scene {scene}: {camera} images {images[0].path.name} and {image.path.name} have different "
                f"calibrations ({first.token}, {other.token}); attribute.json holds one per camera"
            )
    k = np.asarray(first.intrinsic, dtype=float)
    distortion = [0.0] * DISTORTION_LENGTH
    return {
        "K": k.tolist(),
        "d": distortion,
        "distort": distortion,
        "image_width": int(first.width),
        "image_height": int(first.height),
        "focal_u": float(k[0, 0]),
        "focal_v": float(k[1, 1]),
        "center_u": float(k[0, 2]),
        "center_v": float(k[1, 2]),
        "fov": math.degrees(2.0 * math.atan(first.width / (2.0 * k[0, 0]))),
    }


def attribute_json(scene: Scene, sync: ClipSync) -> dict[str, Any]:
    """The whole `attribute.json` of a scene: start/end time, sync lists and calibration."""
    if not sync.rows:
        raise ValueError(
            f"scene {scene.name}: no camera_front image has an image of every camera within the sync "
            f"tolerance ({len(sync.dropped)} dropped); CAMA's code needs at least one synchronised frame"
        )
    calibration: dict[str, Any] = {}
    for name, images in sync.images().items():
        calibration[f"{name}_2_{CHASSIS}"] = images[0].calibration.ego_from_cam.matrix().tolist()
        calibration[name] = camera_calibration(scene.name, name, images)
    times = [f.timestamp_us for f in scene.frames] or [
        row[REFERENCE_CAMERA].timestamp_us for row in sync.rows
    ]
    return {
        "start_time": timestamp_ms(min(times)),
        "end_time": timestamp_ms(max(times)),
        "sync": sync.timestamps_ms(),
        "calibration": calibration,
    }
