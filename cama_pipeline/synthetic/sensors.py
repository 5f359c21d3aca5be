"""Simulated CAN-bus sensors (IMU, wheel speeds, GNSS) and the coarse logged ego pose, from the true motion.

Every simulator takes the clip's `TrueMotion`, a `SensorNoiseConfig` and a `np.random.Generator`, so the same
motion, config and generator state give identical output. Records follow `cama_pipeline.data.schema`: integer
`utime` in microseconds and plain Python floats/lists/bools, ready for `json.dump`.
"""

import logging
import math
from dataclasses import dataclass, fields
from typing import Any, NoReturn

import numpy as np

from cama_pipeline.data.schema import GNSS_MESSAGE, IMU_MESSAGE, WHEEL_MESSAGE, WHEEL_RADIUS_M
from cama_pipeline.synthetic.motion import TrueMotion, matrix_to_quat, quat_multiply, rot_z, so3_exp

logger = logging.getLogger(__name__)

Record = dict[str, Any]

GRAVITY_GLOBAL = np.array([0.0, 0.0, -9.81])
"""Gravity acceleration in the global frame (z up), m/s^2."""
DEGRADED_SIGMA_SCALE = 3.0
"""GNSS fixes just after the dropout are this much noisier (and say so in `std_m`)."""
_LATERAL_GRID_S = 0.5
"""Knot spacing of the smooth lateral wander of the coarse pose."""


@dataclass(frozen=True)
class SensorNoiseConfig:
    """Error figures of the simulated sensors and of the coarse logged ego pose (automotive grade)."""

    # IMU (mounted at the ego origin, axes along the ego axes)
    imu_rate_hz: float = 100.0
    """IMU sample rate (`ms_imu` is 100 Hz in nuScenes)."""
    gyro_noise_density_rad_s_rthz: float = 2.0e-4
    """Gyro white noise, rad/s/sqrt(Hz) (about 0.7 deg/sqrt(h)); per-sample sigma = density * sqrt(rate)."""
    gyro_bias_sigma_rad_s: float = 3.0e-4
    """1-sigma of the constant gyro bias drawn per clip and axis (about 60 deg/h)."""
    gyro_bias_walk_rad_s_rts: float = 1.0e-5
    """Gyro bias random walk, rad/s per sqrt(s)."""
    accel_noise_density_m_s2_rthz: float = 1.0e-3
    """Accelerometer white noise, m/s^2/sqrt(Hz) (about 100 micro-g/sqrt(Hz))."""
    accel_bias_sigma_m_s2: float = 0.02
    """1-sigma of the constant accelerometer bias drawn per clip and axis."""
    accel_bias_walk_m_s2_rts: float = 2.0e-4
    """Accelerometer bias random walk, m/s^2 per sqrt(s)."""
    # wheel speeds
    wheel_rate_hz: float = 100.0
    """Wheel-speed sample rate (`zoe_veh_info` is 100 Hz in nuScenes)."""
    wheel_noise_rpm: float = 0.5
    """1-sigma white noise on each wheel speed reading, rpm (1 rpm is about 3 cm/s)."""
    wheel_radius_scale_sigma: float = 0.004
    """1-sigma of each wheel's effective-radius scale error (tyres), drawn per clip, cut at 3 sigma."""
    wheel_track_m: float = 1.5
    """Distance between the left and right wheels."""
    wheel_base_m: float = 2.588
    """Distance from the rear to the (steered) front axle; front wheels spin faster in turns."""
    wheel_min_speed_mps: float = 0.05
    """Wheels slower than this read exactly 0 (the encoder sees no ticks)."""
    # GNSS (antenna at the ego origin)
    gnss_rate_hz: float = 5.0
    """GNSS fix rate."""
    gnss_horizontal_sigma_m: float = 1.0
    """1-sigma of the east and north errors (white), also reported in `std_m`."""
    gnss_vertical_sigma_m: float = 2.0
    """1-sigma of the up error (white), also reported in `std_m`."""
    gnss_outliers: bool = True
    """Whether to add multipath outliers (single-fix horizontal jumps)."""
    gnss_outlier_prob: float = 0.02
    """Probability that a fix is an outlier (when `gnss_outliers`)."""
    gnss_outlier_jump_m: tuple[float, float] = (5.0, 20.0)
    """Range of an outlier's horizontal jump, metres (uniform magnitude, random direction)."""
    gnss_dropout_s: float = 3.0
    """Length of the one window per clip without fixes (capped at a third of the clip); 0 disables it."""
    gnss_reacquire_s: float = 1.0
    """Fixes this long after the dropout report fix=False and DEGRADED_SIGMA_SCALE times the sigmas."""
    # coarse ego pose (what the car logs as `ego_pose`)
    pose_sync_offset_s: float = 0.02
    """The pose logged at time t is the truth at t + this (time-sync error), a vehicle constant."""
    pose_yaw_calibration_deg: float = 0.3
    """Constant yaw error of the pose (IMU-to-vehicle mounting calibration), a vehicle constant."""
    pose_lever_arm_m: tuple[float, float, float] = (0.04, -0.025, 0.02)
    """The pose locates this ego-frame point instead of the ego origin (about 5 cm), a vehicle constant."""
    pose_heading_drift_deg_s: float = 0.01
    """Largest heading drift rate; each clip draws 0.5-1 times it, signed, accumulating from its start."""
    pose_scale_error: float = 0.01
    """Largest along-track scale error; each clip draws 0.5-1 times it, signed, anchored at mid-clip."""
    pose_lateral_sigma_m: float = 0.25
    """1-sigma of the slowly wandering lateral position error."""
    pose_lateral_time_s: float = 10.0
    """Correlation time of the lateral wander (its rate is about sigma / time)."""
    pose_z_drift_m_s: float = 0.005
    """Largest vertical drift rate; each clip draws 0.5-1 times it with a random sign."""

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name == "gnss_outliers":
                if not isinstance(value, bool):
                    _reject(f.name, "a bool", value)
                continue
            items = value if isinstance(value, tuple) else (value,)
            if not all(
                isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) for v in items
            ):
                _reject(f.name, "finite number(s)", value)
        for name in _POSITIVE_FIELDS:
            if getattr(self, name) <= 0:
                _reject(name, "> 0", getattr(self, name))
        for name in _NONNEGATIVE_FIELDS:
            if getattr(self, name) < 0:
                _reject(name, ">= 0", getattr(self, name))
        self._check_ranges()

    def _check_ranges(self) -> None:
        """Checks of fields with upper bounds or structure (tuples)."""
        if not 0.0 <= self.gnss_outlier_prob < 1.0:
            _reject("gnss_outlier_prob", "in [0, 1)", self.gnss_outlier_prob)
        jump = self.gnss_outlier_jump_m
        if len(jump) != 2 or not 0 < jump[0] <= jump[1]:
            _reject("gnss_outlier_jump_m", "a (low, high) pair with 0 < low <= high", jump)
        if len(self.pose_lever_arm_m) != 3:
            _reject("pose_lever_arm_m", "an (x, y, z) triple", self.pose_lever_arm_m)
        if self.wheel_radius_scale_sigma >= 0.05:
            _reject("wheel_radius_scale_sigma", "< 0.05", self.wheel_radius_scale_sigma)
        if self.pose_scale_error >= 0.1:
            _reject("pose_scale_error", "< 0.1", self.pose_scale_error)
        if abs(self.pose_sync_offset_s) > 0.5:
            _reject("pose_sync_offset_s", "within +-0.5 s", self.pose_sync_offset_s)
        if abs(self.pose_yaw_calibration_deg) > 5.0:
            _reject("pose_yaw_calibration_deg", "within +-5 deg", self.pose_yaw_calibration_deg)


_POSITIVE_FIELDS: tuple[str, ...] = (
    "imu_rate_hz",
    "wheel_rate_hz",
    "gnss_rate_hz",
    "wheel_track_m",
    "wheel_base_m",
    "pose_lateral_time_s",
)
_NONNEGATIVE_FIELDS: tuple[str, ...] = (
    "gyro_noise_density_rad_s_rthz",
    "gyro_bias_sigma_rad_s",
    "gyro_bias_walk_rad_s_rts",
    "accel_noise_density_m_s2_rthz",
    "accel_bias_sigma_m_s2",
    "accel_bias_walk_m_s2_rts",
    "wheel_noise_rpm",
    "wheel_radius_scale_sigma",
    "wheel_min_speed_mps",
    "gnss_horizontal_sigma_m",
    "gnss_vertical_sigma_m",
    "gnss_dropout_s",
    "gnss_reacquire_s",
    "pose_heading_drift_deg_s",
    "pose_scale_error",
    "pose_lateral_sigma_m",
    "pose_z_drift_m_s",
)


def _reject(name: str, rule: str, value: object) -> NoReturn:
    """Raise the ValueError naming the offending config field."""
    raise ValueError(f"SensorNoiseConfig.{name} must be {rule}, got {value!r}")


def sample_times_us(motion: TrueMotion, rate_hz: float) -> np.ndarray:
    """Timestamps at `rate_hz` from the clip's first sample up to its last (int64 microseconds)."""
    t0, t1 = int(motion.times_us[0]), int(motion.times_us[-1])
    n = int(math.floor((t1 - t0) * 1e-6 * rate_hz + 1e-9)) + 1
    return np.minimum(t0 + np.round(np.arange(n) * 1e6 / rate_hz).astype(np.int64), t1)


def _bias(rng: np.random.Generator, n: int, dt_s: float, sigma: float, walk: float) -> np.ndarray:
    """(n, 3) sensor bias: a constant per axis plus a random walk."""
    steps = rng.normal(0.0, walk * math.sqrt(dt_s), (n, 3))
    steps[0] = 0.0
    return rng.normal(0.0, sigma, 3) + np.cumsum(steps, axis=0)


def _integrate_attitude(q0_wxyz: np.ndarray, gyro: np.ndarray, dt_s: float) -> np.ndarray:
    """(n, 4) attitudes integrating body rates (trapezoid steps) from `q0`, by a parallel prefix product."""
    steps = matrix_to_quat(so3_exp(0.5 * (gyro[:-1] + gyro[1:]) * dt_s))
    prefix = np.concatenate([q0_wxyz[None], steps])
    offset = 1
    while offset < len(prefix):
        prefix[offset:] = quat_multiply(prefix[:-offset], prefix[offset:])
        offset *= 2
    prefix /= np.linalg.norm(prefix, axis=1, keepdims=True)
    return prefix * np.where(prefix[:, :1] < 0, -1.0, 1.0)


def simulate_imu(motion: TrueMotion, cfg: SensorNoiseConfig, rng: np.random.Generator) -> list[Record]:
    """`ms_imu` records: specific force and gyro rate with bias and noise, and gyro-integrated attitude."""
    times = sample_times_us(motion, cfg.imu_rate_hz)
    n, dt = len(times), 1.0 / cfg.imu_rate_hz
    R, _ = motion.interpolate(times)
    accel = motion.interpolate_rows(motion.accel_global, times)
    rate = motion.interpolate_rows(motion.angular_rate_ego, times)
    gyro_sigma = cfg.gyro_noise_density_rad_s_rthz * math.sqrt(cfg.imu_rate_hz)
    accel_sigma = cfg.accel_noise_density_m_s2_rthz * math.sqrt(cfg.imu_rate_hz)
    gyro = rate + _bias(rng, n, dt, cfg.gyro_bias_sigma_rad_s, cfg.gyro_bias_walk_rad_s_rts)
    gyro += rng.normal(0.0, gyro_sigma, (n, 3))
    force = np.einsum("nji,nj->ni", R, accel - GRAVITY_GLOBAL)
    force += _bias(rng, n, dt, cfg.accel_bias_sigma_m_s2, cfg.accel_bias_walk_m_s2_rts)
    force += rng.normal(0.0, accel_sigma, (n, 3))
    q = _integrate_attitude(matrix_to_quat(R[0]), gyro, dt)
    return [
        {"utime": int(t), "linear_accel": f.tolist(), "rotation_rate": g.tolist(), "q": qq.tolist()}
        for t, f, g, qq in zip(times, force, gyro, q, strict=True)
    ]


def true_wheel_speeds_mps(
    velocity_ego: np.ndarray, yaw_rate: np.ndarray, cfg: SensorNoiseConfig
) -> np.ndarray:
    """(n, 4) signed rolling speeds FL, FR, RL, RR (m/s): inner wheels slower, steered front wheels faster."""
    half = 0.5 * cfg.wheel_track_m
    vx, vy = velocity_ego[:, 0], velocity_ego[:, 1]
    left_x, right_x = vx - yaw_rate * half, vx + yaw_rate * half
    front_y = vy + yaw_rate * cfg.wheel_base_m
    front_left = np.sign(left_x) * np.hypot(left_x, front_y)
    front_right = np.sign(right_x) * np.hypot(right_x, front_y)
    return np.stack([front_left, front_right, left_x, right_x], axis=1)


def simulate_wheels(motion: TrueMotion, cfg: SensorNoiseConfig, rng: np.random.Generator) -> list[Record]:
    """`zoe_veh_info` records: wheel speeds in rpm with per-wheel radius scale error and noise, 0 at rest."""
    times = sample_times_us(motion, cfg.wheel_rate_hz)
    velocity = motion.interpolate_rows(motion.velocity_ego, times)
    yaw_rate = motion.interpolate_rows(motion.angular_rate_ego, times)[:, 2]
    speeds = true_wheel_speeds_mps(velocity, yaw_rate, cfg)
    sigma = cfg.wheel_radius_scale_sigma
    radius_scale = 1.0 + np.clip(rng.normal(0.0, sigma, 4), -3 * sigma, 3 * sigma)
    logger.debug("wheel radius scales %s", radius_scale)
    rpm = speeds / (2 * math.pi * WHEEL_RADIUS_M * radius_scale) * 60.0
    noisy = rpm + rng.normal(0.0, cfg.wheel_noise_rpm, rpm.shape)
    noisy = np.where(rpm > 0, np.maximum(noisy, 0.0), np.minimum(noisy, 0.0))
    noisy[np.abs(speeds) < cfg.wheel_min_speed_mps] = 0.0
    return [
        {
            "utime": int(t),
            "FL_wheel_speed": float(w[0]),
            "FR_wheel_speed": float(w[1]),
            "RL_wheel_speed": float(w[2]),
            "RR_wheel_speed": float(w[3]),
        }
        for t, w in zip(times, noisy, strict=True)
    ]


def _dropout_window_us(
    rng: np.random.Generator, motion: TrueMotion, cfg: SensorNoiseConfig
) -> tuple[int, int]:
    """[start, stop) of the clip's one GNSS outage: at most a third of the clip, away from its ends."""
    duration = motion.duration_s
    length = min(cfg.gnss_dropout_s, duration / 3.0)
    start = int(motion.times_us[0]) + (0.1 * duration + rng.uniform() * (0.8 * duration - length)) * 1e6
    return int(round(start)), int(round(start + length * 1e6))


def _outlier_jumps(rng: np.random.Generator, n: int, cfg: SensorNoiseConfig) -> np.ndarray:
    """(n, 3) horizontal multipath jumps, zero except on the fixes drawn as outliers."""
    hit = rng.uniform(size=n) < cfg.gnss_outlier_prob
    magnitude = rng.uniform(*cfg.gnss_outlier_jump_m, size=n) * hit
    angle = rng.uniform(0.0, 2 * math.pi, size=n)
    return np.stack([magnitude * np.cos(angle), magnitude * np.sin(angle), np.zeros(n)], axis=1)


def simulate_gnss(motion: TrueMotion, cfg: SensorNoiseConfig, rng: np.random.Generator) -> list[Record]:
    """`gnss` records: ego-origin positions with white noise, outliers (if enabled) and one dropout window."""
    times = sample_times_us(motion, cfg.gnss_rate_hz)
    _, position = motion.interpolate(times)
    sigma = np.array([cfg.gnss_horizontal_sigma_m, cfg.gnss_horizontal_sigma_m, cfg.gnss_vertical_sigma_m])
    noise = rng.normal(size=(len(times), 3)) * sigma
    # outliers are drawn either way, so toggling them leaves the rest of the output unchanged
    jumps = _outlier_jumps(rng, len(times), cfg)
    start, stop = _dropout_window_us(rng, motion, cfg)
    degraded = (times >= stop) & (times < stop + cfg.gnss_reacquire_s * 1e6) & (stop > start)
    scale = np.where(degraded, DEGRADED_SIGMA_SCALE, 1.0)[:, None]
    measured = position + noise * scale + (jumps if cfg.gnss_outliers else 0.0)
    keep = (times < start) | (times >= stop)
    logger.debug("GNSS dropout %d..%d us, %d outliers", start, stop, int(np.count_nonzero(jumps[:, 0])))
    return [
        {"utime": int(t), "pos": p.tolist(), "std_m": (sigma * s).tolist(), "fix": not bool(d)}
        for t, p, s, d, k in zip(times, measured, scale[:, 0], degraded, keep, strict=True)
        if k
    ]


@dataclass(frozen=True)
class _PoseDrift:
    """Per-clip draws of the coarse pose's slowly varying errors."""

    heading_rate_rad_s: float
    scale: float
    z_rate_m_s: float
    lateral_grid_s: np.ndarray
    lateral_m: np.ndarray


def _signed_draw(rng: np.random.Generator, largest: float) -> float:
    """A value of magnitude 0.5-1 times `largest` with a random sign."""
    return float(largest * rng.uniform(0.5, 1.0) * (1.0 if rng.uniform() < 0.5 else -1.0))


def smooth_noise(
    rng: np.random.Generator, duration_s: float, sigma: float, corr_s: float, step_s: float
) -> np.ndarray:
    """Smooth zero-mean noise of std `sigma` (Gaussian-filtered white noise) on a grid of `step_s` from 0."""
    kernel_std = 0.5 * corr_s
    half = int(math.ceil(3.0 * kernel_std / step_s))
    n = int(math.ceil(duration_s / step_s)) + 2
    kernel = np.exp(-0.5 * (np.arange(-half, half + 1) * step_s / kernel_std) ** 2)
    kernel /= np.sqrt(np.sum(kernel**2))
    return sigma * np.convolve(rng.normal(size=n + 2 * half), kernel, mode="valid")


def _draw_pose_drift(rng: np.random.Generator, motion: TrueMotion, cfg: SensorNoiseConfig) -> _PoseDrift:
    """Draw the clip's heading drift rate, scale error, z drift and lateral wander (logged at debug level)."""
    lateral_m = smooth_noise(
        rng, motion.duration_s, cfg.pose_lateral_sigma_m, cfg.pose_lateral_time_s, _LATERAL_GRID_S
    )
    drift = _PoseDrift(
        heading_rate_rad_s=math.radians(_signed_draw(rng, cfg.pose_heading_drift_deg_s)),
        scale=_signed_draw(rng, cfg.pose_scale_error),
        z_rate_m_s=_signed_draw(rng, cfg.pose_z_drift_m_s),
        lateral_grid_s=np.arange(len(lateral_m)) * _LATERAL_GRID_S,
        lateral_m=lateral_m,
    )
    logger.debug(
        "coarse pose drift: heading %.2e rad/s, scale %.4f, z %.4f m/s",
        drift.heading_rate_rad_s,
        drift.scale,
        drift.z_rate_m_s,
    )
    return drift


def coarse_ego_poses(
    motion: TrueMotion, times_us: np.ndarray, cfg: SensorNoiseConfig, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """Coarse global_from_ego poses (R (M,3,3), t (M,3)) logged at `times_us`: truth plus smooth drift."""
    q = np.atleast_1d(np.asarray(times_us, dtype=np.int64))
    R_now, t_now = motion.interpolate(q)  # raises the range error for times outside the clip
    drift = _draw_pose_drift(rng, motion, cfg)
    # truth at t + sync offset, to first order (smooth up to the clip's ends, where interpolation would clamp)
    offset_s = cfg.pose_sync_offset_s
    R = R_now @ so3_exp(motion.interpolate_rows(motion.angular_rate_ego, q) * offset_s)
    t = t_now + motion.interpolate_rows(motion.velocity_global, q) * offset_s
    t0 = int(motion.times_us[0])
    elapsed_s = (q - t0) * 1e-6
    calib = rot_z(math.radians(cfg.pose_yaw_calibration_deg))
    coarse_R = rot_z(drift.heading_rate_rad_s * elapsed_s) @ R @ calib
    left = R[:, :, 1] * np.array([1.0, 1.0, 0.0])
    left /= np.maximum(np.linalg.norm(left, axis=1, keepdims=True), 1e-9)
    anchor = motion.global_from_ego_t[len(motion.times_us) // 2]
    lateral = np.interp(elapsed_s, drift.lateral_grid_s, drift.lateral_m)
    coarse_t = t + R @ np.asarray(cfg.pose_lever_arm_m) + drift.scale * (t - anchor) + lateral[:, None] * left
    coarse_t[:, 2] += drift.z_rate_m_s * elapsed_s
    return coarse_R, coarse_t


def simulate_can(
    motion: TrueMotion, cfg: SensorNoiseConfig, rng: np.random.Generator
) -> dict[str, list[Record]]:
    """All CAN-bus messages of a clip, keyed by the schema's message names."""
    return {
        IMU_MESSAGE: simulate_imu(motion, cfg, rng),
        WHEEL_MESSAGE: simulate_wheels(motion, cfg, rng),
        GNSS_MESSAGE: simulate_gnss(motion, cfg, rng),
    }
