"""Wheel + gyro dead reckoning: the clip's relative motion, and the noise of each step between graph nodes.

The 2.5-D odometry model: the body moves along its own x axis at the rear-axle speed (mean of the two rear
wheels; non-holonomic, no side slip) and turns at the gyro's rate (or, without an IMU, at the yaw rate the
rear-wheel speed difference implies). Rotations are integrated in 3-D, so pitch from the gyro carries the
path up and down slopes; the accelerometer's gravity direction (`cama_pipeline.wigo.attitude`) pins roll
and pitch in the graph.
"""

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from cama_pipeline.data.schema import WHEEL_RADIUS_M
from cama_pipeline.wigo.config import WigoConfig
from cama_pipeline.wigo.inputs import ClipInputs

RPM_TO_MPS = 2.0 * math.pi * WHEEL_RADIUS_M / 60.0
"""Wheel rpm to rolling speed in m/s."""


@dataclass(frozen=True, eq=False)
class DeadReckoning:
    """Integrated odometry on a time grid: poses relative to the grid's first instant."""

    times_us: np.ndarray
    """(M,) int64 grid times, increasing."""
    rotation: np.ndarray
    """(M, 3, 3) start_from_body rotations."""
    translation: np.ndarray
    """(M, 3) body position in the start frame, metres."""
    speed_mps: np.ndarray
    """(M,) rear-axle speed used at each grid time."""
    yaw_rate_rad_s: np.ndarray
    """(M,) body yaw rate used at each grid time."""


def _interp(times_us: np.ndarray, series_us: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Linear interpolation of rows `values` (N, k) at `times_us`, constant beyond the series' ends."""
    x = (times_us - series_us[0]).astype(np.float64)
    base = (series_us - series_us[0]).astype(np.float64)
    return np.stack([np.interp(x, base, values[:, k]) for k in range(values.shape[1])], axis=1)


def body_rates(inputs: ClipInputs, times_us: np.ndarray, config: WigoConfig) -> tuple[np.ndarray, np.ndarray]:
    """(speed (M,), angular rate (M, 3)) at `times_us`: rear-axle speed, gyro (or wheel yaw rate)."""
    wheel = inputs.wheel
    rear = _interp(times_us, wheel.utime, wheel.speed_rpm[:, 2:4]) * RPM_TO_MPS
    speed = rear.mean(axis=1)
    if inputs.imu is not None:
        rate = _interp(times_us, inputs.imu.utime, inputs.imu.rotation_rate)
    else:
        rate = np.zeros((len(times_us), 3))
        rate[:, 2] = (rear[:, 1] - rear[:, 0]) / config.wheel_track_m
    return speed, rate


def integration_grid(start_us: int, stop_us: int, extra_us: np.ndarray, rate_hz: float) -> np.ndarray:
    """Sorted unique times: a regular grid from `start_us` to `stop_us` plus `extra_us` within them."""
    step = 1e6 / rate_hz
    n = max(int(math.ceil((stop_us - start_us) / step)), 0)
    grid = start_us + np.round(np.arange(n + 1) * step).astype(np.int64)
    grid = np.concatenate([np.minimum(grid, stop_us), [stop_us], extra_us])
    return np.unique(grid[(grid >= start_us) & (grid <= stop_us)])


def dead_reckon(inputs: ClipInputs, times_us: np.ndarray, config: WigoConfig) -> DeadReckoning:
    """Integrate speed and angular rate over the grid `times_us` (midpoint rule), starting at identity."""
    speed, rate = body_rates(inputs, times_us, config)
    dt = np.diff(times_us).astype(np.float64) * 1e-6
    mid_rate = 0.5 * (rate[:-1] + rate[1:])
    mid_speed = 0.5 * (speed[:-1] + speed[1:])
    steps = Rotation.from_rotvec(mid_rate * dt[:, None]).as_matrix()
    half = Rotation.from_rotvec(0.5 * mid_rate * dt[:, None]).as_matrix()
    rotation = np.empty((len(times_us), 3, 3))
    translation = np.zeros((len(times_us), 3))
    rotation[0] = np.eye(3)
    for k in range(len(dt)):
        heading = rotation[k] @ half[k]
        translation[k + 1] = translation[k] + heading[:, 0] * (mid_speed[k] * dt[k])
        rotation[k + 1] = rotation[k] @ steps[k]
    return DeadReckoning(times_us, rotation, translation, speed, rate[:, 2])


def relative_poses(odometry: DeadReckoning, node_times_us: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(R (K-1, 3, 3), t (K-1, 3)): node k's pose in node k-1's frame, from the dead reckoning."""
    index = np.searchsorted(odometry.times_us, node_times_us)
    R, t = odometry.rotation[index], odometry.translation[index]
    R_prev_T = np.swapaxes(R[:-1], 1, 2)
    return R_prev_T @ R[1:], np.einsum("kij,kj->ki", R_prev_T, t[1:] - t[:-1])


def step_sigmas(
    odometry: DeadReckoning, node_times_us: np.ndarray, config: WigoConfig, has_imu: bool
) -> np.ndarray:
    """(K-1, 6) sigmas [rx, ry, rz, tx, ty, tz] of each node-to-node odometry step (gtsam's order)."""
    index = np.searchsorted(odometry.times_us, node_times_us)
    dt = np.diff(node_times_us).astype(np.float64) * 1e-6
    distance = np.abs(np.diff(np.concatenate([[0.0], np.cumsum(_step_lengths(odometry))])[index]))
    gyro = np.sqrt(config.gyro_noise_rad_s_rthz**2 * dt + (config.gyro_bias_rad_s * dt) ** 2)
    # without an IMU, tilt is held by the odometry and yaw comes from the wheels: both get the wheel rate error
    yaw = gyro if has_imu else config.no_imu_yaw_rate_sigma_rad_s * dt
    tilt = yaw
    along = np.hypot(config.wheel_speed_sigma_mps * dt, config.wheel_scale_sigma * distance)
    across = config.lateral_slip_sigma_mps * dt
    floor = 1e-4
    sigmas = np.stack([tilt, tilt, yaw, along, across, across], axis=1)
    return np.maximum(sigmas, floor)


def _step_lengths(odometry: DeadReckoning) -> np.ndarray:
    """(M-1,) distance travelled in each grid step."""
    return np.linalg.norm(np.diff(odometry.translation, axis=0), axis=1)
