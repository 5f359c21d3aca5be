"""The measurements WIGO fuses for one clip, taken from a loaded scene and checked before any maths.

Bad input is named here: series out of time order are sorted (with a warning), repeated timestamps and
clips without camera images or wheel speeds are refused with a ValueError naming the scene and series,
missing IMU or GNSS are allowed (the fusion degrades, see `cama_pipeline.wigo.fusion`).
"""

import logging
from dataclasses import dataclass, replace
from typing import TypeVar

import numpy as np

from cama_pipeline.data import GnssSeries, ImuSeries, Scene, WheelSeries
from cama_pipeline.data.schema import GNSS_MESSAGE, IMU_MESSAGE, WHEEL_MESSAGE

logger = logging.getLogger(__name__)

_Series = TypeVar("_Series", ImuSeries, WheelSeries, GnssSeries)


@dataclass(frozen=True, eq=False)
class LoggedPoses:
    """The logged (coarse) `ego_pose` of every camera image of a clip, in time order."""

    tokens: tuple[str, ...]
    """sample_data token of each image."""
    channels: tuple[str, ...]
    """Camera channel of each image."""
    times_us: np.ndarray
    """(N,) int64 capture times, non-decreasing."""
    rotation: np.ndarray
    """(N, 3, 3) logged global_from_ego rotations."""
    translation: np.ndarray
    """(N, 3) logged global_from_ego translations, metres."""


@dataclass(frozen=True, eq=False)
class ClipInputs:
    """Everything the fusion of one clip reads: camera times with their logged poses and the CAN series."""

    scene: str
    """Scene name (for messages and output files)."""
    cameras: LoggedPoses
    """Camera images (the times poses are wanted at) and their logged ego poses."""
    wheel: WheelSeries
    """Wheel speeds (required: the odometry's scale)."""
    imu: ImuSeries | None
    """IMU, or None (yaw rate then comes from the wheels, roll and pitch from the logged pose)."""
    gnss: GnssSeries | None
    """GNSS fixes, or None (the logged ego pose is then the clip's only global constraint)."""


class NoWheelSpeeds(ValueError):
    """A clip without usable wheel speeds: no odometry scale to fuse (`WigoConfig.without_wheels` decides)."""


def logged_poses(scene: Scene) -> LoggedPoses:
    """The logged ego pose of every camera image of a loaded scene; ValueError naming the scene when it has no
    images or their timestamps are out of order."""
    images = scene.all_images()
    if not images:
        raise ValueError(f"scene {scene.name!r}: no camera images, nothing to estimate poses for")
    cameras = LoggedPoses(
        tokens=tuple(im.token for im in images),
        channels=tuple(im.channel for im in images),
        times_us=np.array([im.timestamp_us for im in images], dtype=np.int64),
        rotation=np.stack([im.global_from_ego.rotation_matrix() for im in images]),
        translation=np.stack([im.global_from_ego.translation for im in images]),
    )
    _check_camera_order(scene.name, cameras.times_us)
    return cameras


def _check_camera_order(scene: str, times_us: np.ndarray) -> None:
    """ValueError naming the scene when its camera times go back (poses are interpolated in time order)."""
    if np.any(np.diff(times_us) < 0):
        raise ValueError(f"scene {scene!r}: camera timestamps are not in time order")


def clip_inputs(scene: Scene, cameras: LoggedPoses | None = None) -> ClipInputs:
    """The checked inputs of a loaded scene (see the module docstring for what is refused; NoWheelSpeeds for a
    scene without wheel speeds); `cameras`: its `logged_poses` when the caller has them already."""
    cameras = logged_poses(scene) if cameras is None else cameras
    if scene.can.wheel is None:
        raise _no_wheels(scene.name)
    return checked_inputs(ClipInputs(scene.name, cameras, scene.can.wheel, scene.can.imu, scene.can.gnss))


def _no_wheels(scene: str) -> NoWheelSpeeds:
    """The error for a clip without usable wheel speeds."""
    return NoWheelSpeeds(
        f"scene {scene!r}: no wheel speeds ({WHEEL_MESSAGE}, at least 2 messages needed); "
        'WIGO needs them for the odometry\'s scale ([wigo] without_wheels = "logged_pose" passes the logged '
        "ego poses through instead)"
    )


def checked_inputs(inputs: ClipInputs) -> ClipInputs:
    """`inputs` with every series in time order; ValueError for what cannot be repaired."""
    name = inputs.scene
    if len(inputs.cameras.times_us) == 0:
        raise ValueError(f"scene {name!r}: no camera images, nothing to estimate poses for")
    _check_camera_order(name, inputs.cameras.times_us)
    if inputs.wheel is None or len(inputs.wheel.utime) < 2:
        raise _no_wheels(name)
    wheel = _in_time_order(inputs.wheel, name, WHEEL_MESSAGE)
    imu = _in_time_order(inputs.imu, name, IMU_MESSAGE) if inputs.imu is not None else None
    if imu is not None and len(imu.utime) < 2:
        logger.warning("scene %s: fewer than 2 %s messages, running without the IMU", name, IMU_MESSAGE)
        imu = None
    elif imu is None:
        logger.warning(
            "scene %s: no IMU (%s): yaw rate from the rear wheels, no gravity factors", name, IMU_MESSAGE
        )
    gnss = _in_time_order(inputs.gnss, name, GNSS_MESSAGE) if inputs.gnss is not None else None
    if gnss is None or len(gnss.utime) == 0:
        logger.warning(
            "scene %s: no GNSS fixes (%s): the logged ego pose is the global constraint", name, GNSS_MESSAGE
        )
        gnss = None
    return replace(inputs, wheel=wheel, imu=imu, gnss=gnss)


def _in_time_order(series: _Series, scene: str, message: str) -> _Series:
    """The series sorted by `utime` (warning when it was not); ValueError on repeated timestamps."""
    utime = series.utime
    if len(np.unique(utime)) != len(utime):
        first = int(utime[np.flatnonzero(np.diff(np.sort(utime)) == 0)[0]])
        raise ValueError(f"scene {scene!r}: {message} has two messages with utime {first}")
    if np.all(np.diff(utime) > 0):
        return series
    logger.warning("scene %s: %s messages are out of time order: sorting them", scene, message)
    order = np.argsort(utime, kind="stable")
    values = {
        name: np.asarray(getattr(series, name))[order]
        for name in series.__dataclass_fields__  # every field is a per-message array
    }
    return type(series)(**values)
