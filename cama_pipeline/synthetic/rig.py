"""The six-camera nuScenes rig: intrinsics and ego_from_cam extrinsics close to the real calibration."""

from dataclasses import dataclass

import numpy as np

from cama_pipeline.synthetic.config import CameraConfig

NUSCENES_WIDTH_PX, NUSCENES_HEIGHT_PX = 1600, 900

# channel: (translation in ego [m], yaw [deg, left positive], pitch down [deg], fx, cx, cy at 1600x900)
_NUSCENES_RIG: dict[str, tuple[tuple[float, float, float], float, float, float, float, float]] = {
    "CAM_FRONT": ((1.70, 0.016, 1.511), 0.0, 0.6, 1266.4, 816.3, 491.5),
    "CAM_FRONT_RIGHT": ((1.551, -0.493, 1.496), -55.0, 0.8, 1260.8, 808.0, 495.3),
    "CAM_BACK_RIGHT": ((1.015, -0.480, 1.562), -110.0, 0.5, 1259.5, 807.3, 501.2),
    "CAM_BACK": ((0.028, 0.003, 1.579), 180.0, 1.5, 809.2, 829.2, 481.8),
    "CAM_BACK_LEFT": ((1.036, 0.485, 1.591), 110.0, 0.4, 1256.7, 817.8, 452.0),
    "CAM_FRONT_LEFT": ((1.524, 0.495, 1.510), 55.0, 0.9, 1272.6, 826.6, 479.8),
}

# Trigger offset of each camera after the sweep's nominal time, as the nuScenes cameras fire one after
# another while the lidar turns.
CAMERA_OFFSET_US: dict[str, int] = {
    "CAM_FRONT": 12_000,
    "CAM_FRONT_RIGHT": 20_500,
    "CAM_BACK_RIGHT": 37_000,
    "CAM_BACK": 45_500,
    "CAM_BACK_LEFT": 3_500,
    "CAM_FRONT_LEFT": 29_000,
}


@dataclass(frozen=True)
class RigCamera:
    """One camera: pinhole intrinsics and its pose on the vehicle (OpenCV camera axes)."""

    channel: str
    width_px: int
    height_px: int
    K: np.ndarray  # (3, 3)
    ego_from_cam_R: np.ndarray  # (3, 3)
    ego_from_cam_t: np.ndarray  # (3,)
    offset_us: int


def ego_from_cam_rotation(yaw_deg: float, pitch_down_deg: float) -> np.ndarray:
    """Rotation whose columns are the camera's x (right), y (down) and z (forward) axes in the ego frame."""
    yaw, pitch = np.radians(yaw_deg), np.radians(pitch_down_deg)
    z_axis = np.array([np.cos(yaw) * np.cos(pitch), np.sin(yaw) * np.cos(pitch), -np.sin(pitch)])
    x_axis = np.array([np.sin(yaw), -np.cos(yaw), 0.0])
    y_axis = np.cross(z_axis, x_axis)
    return np.stack([x_axis, y_axis, z_axis], axis=1)


def build_rig(cfg: CameraConfig) -> tuple[RigCamera, ...]:
    """The six cameras with intrinsics scaled from nuScenes' 1600x900 to the configured size."""
    sx = cfg.width_px / NUSCENES_WIDTH_PX
    sy = cfg.height_px / NUSCENES_HEIGHT_PX
    cameras = []
    for channel, (t, yaw, pitch, f, cx, cy) in _NUSCENES_RIG.items():
        K = np.array([[f * sx, 0.0, cx * sx], [0.0, f * sy, cy * sy], [0.0, 0.0, 1.0]])
        cameras.append(
            RigCamera(
                channel,
                cfg.width_px,
                cfg.height_px,
                K,
                ego_from_cam_rotation(yaw, pitch),
                np.asarray(t, float),
                CAMERA_OFFSET_US[channel],
            )
        )
    return tuple(cameras)
