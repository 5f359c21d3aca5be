"""Hand-made camera views for the pair-selection tests: a car's cameras at a position and heading."""

import numpy as np

from cama_pipeline.cameras import CameraView

WIDTH, HEIGHT = 512, 288
INTRINSIC = np.array([[300.0, 0.0, 256.0], [0.0, 300.0, 144.0], [0.0, 0.0, 1.0]])
CAMERA_HEIGHT_M = 1.5


def ego_pose(x: float, y: float, yaw_deg: float, z: float = 0.0) -> np.ndarray:
    """global_from_ego for a car at (x, y, z) heading `yaw_deg` (0 = +x)."""
    yaw = np.radians(yaw_deg)
    pose = np.eye(4)
    pose[:2, :2] = [[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]]
    pose[:3, 3] = [x, y, z]
    return pose


def ego_from_cam(mount_yaw_deg: float, pitch_down_deg: float = 10.0) -> np.ndarray:
    """A camera 1.5 m up looking along ego yaw `mount_yaw_deg`, pitched down (OpenCV axes)."""
    # camera axes in ego coordinates when looking along +x: z forward, x right (-y), y down (-z)
    look = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
    pitch = -np.radians(pitch_down_deg)  # turns the optical axis towards the image's +y (down)
    tilt = np.array([[1, 0, 0], [0, np.cos(pitch), -np.sin(pitch)], [0, np.sin(pitch), np.cos(pitch)]])
    yaw = np.radians(mount_yaw_deg)
    turn = np.array([[np.cos(yaw), -np.sin(yaw), 0], [np.sin(yaw), np.cos(yaw), 0], [0, 0, 1]])
    pose = np.eye(4)
    pose[:3, :3] = turn @ look @ tilt
    pose[:3, 3] = [1.0, 0.0, CAMERA_HEIGHT_M]
    return pose


def view(
    x: float,
    y: float,
    yaw_deg: float,
    *,
    channel: str = "CAM_FRONT",
    mount_yaw_deg: float = 0.0,
    scene: str = "scene-a",
    frame: int = 0,
    z: float = 0.0,
) -> CameraView:
    """One camera view of a car at (x, y) heading `yaw_deg`."""
    return CameraView(
        name=f"{scene}/{channel}/{frame}.jpg",
        token=f"{scene}-{channel}-{frame}",
        scene=scene,
        channel=channel,
        frame_index=frame,
        timestamp_us=frame * 500_000,
        world_from_ego=ego_pose(x, y, yaw_deg, z),
        ego_from_cam=ego_from_cam(mount_yaw_deg),
        intrinsic=INTRINSIC,
        width=WIDTH,
        height=HEIGHT,
    )
