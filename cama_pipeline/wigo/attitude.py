"""Roll and pitch from the accelerometer: the body's "up" direction, with the vehicle's own acceleration
(along-track from the wheel speed's change, centripetal from speed times yaw rate) taken out first."""

import numpy as np

from cama_pipeline.wigo.config import WigoConfig
from cama_pipeline.wigo.inputs import ClipInputs
from cama_pipeline.wigo.odometry import DeadReckoning


def gravity_up_body(
    inputs: ClipInputs, odometry: DeadReckoning, node_times_us: np.ndarray, config: WigoConfig
) -> np.ndarray | None:
    """(K, 3) unit "up" vectors in the body frame at the nodes, or None without an IMU.

    The specific force is f = R^T (a - g), so R^T (-g) = f - a_body: averaging f over a short window and
    subtracting the body acceleration the wheels and gyro imply leaves gravity, pointing up.
    """
    imu = inputs.imu
    if imu is None:
        return None
    t_s = (odometry.times_us - odometry.times_us[0]) * 1e-6
    accel_along = np.gradient(odometry.speed_mps, t_s) if len(t_s) > 1 else np.zeros(1)
    centripetal = odometry.speed_mps * odometry.yaw_rate_rad_s
    half_us = 0.5 * config.gravity_window_s * 1e6
    up = np.empty((len(node_times_us), 3))
    for k, t in enumerate(node_times_us):
        window = (imu.utime >= t - half_us) & (imu.utime <= t + half_us)
        if not window.any():
            window = np.abs(imu.utime - t) == np.min(np.abs(imu.utime - t))
        force = imu.linear_accel[window].mean(axis=0)
        in_odo = (odometry.times_us >= t - half_us) & (odometry.times_us <= t + half_us)
        if not in_odo.any():
            in_odo = np.abs(odometry.times_us - t) == np.min(np.abs(odometry.times_us - t))
        motion = np.array([accel_along[in_odo].mean(), centripetal[in_odo].mean(), 0.0])
        vector = force - motion
        up[k] = vector / max(float(np.linalg.norm(vector)), 1e-9)
    return up
