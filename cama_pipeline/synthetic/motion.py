"""Ground-truth ego motion of a clip, with its derivatives and interpolation, and small SO(3) helpers."""

import logging
from dataclasses import dataclass
from functools import cached_property
from typing import Literal

import numpy as np
from scipy.spatial.transform import Rotation

logger = logging.getLogger(__name__)


def quat_to_matrix(q_wxyz: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) from quaternions (..., 4) stored w, x, y, z (normalised first)."""
    q = np.asarray(q_wxyz, dtype=float)
    flat = Rotation.from_quat(q.reshape(-1, 4), scalar_first=True).as_matrix()
    return flat.reshape(q.shape[:-1] + (3, 3))


def matrix_to_quat(R: np.ndarray) -> np.ndarray:
    """Quaternions (..., 4) w, x, y, z with w >= 0 from rotation matrices (..., 3, 3)."""
    m = np.asarray(R, dtype=float)
    flat = Rotation.from_matrix(m.reshape(-1, 3, 3)).as_quat(canonical=True, scalar_first=True)
    return flat.reshape(m.shape[:-2] + (4,))


def so3_exp(rotvec: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) from rotation vectors (..., 3) (axis * angle, radians)."""
    v = np.asarray(rotvec, dtype=float)
    return Rotation.from_rotvec(v.reshape(-1, 3)).as_matrix().reshape(v.shape[:-1] + (3, 3))


def so3_log(R: np.ndarray) -> np.ndarray:
    """Rotation vectors (..., 3) of rotation matrices (..., 3, 3), angles in [0, pi]."""
    m = np.asarray(R, dtype=float)
    return Rotation.from_matrix(m.reshape(-1, 3, 3)).as_rotvec().reshape(m.shape[:-2] + (3,))


def quat_multiply(a_wxyz: np.ndarray, b_wxyz: np.ndarray) -> np.ndarray:
    """Hamilton product a * b of quaternions (..., 4) stored w, x, y, z (broadcasting)."""
    aw, ax, ay, az = np.moveaxis(np.asarray(a_wxyz, dtype=float), -1, 0)
    bw, bx, by, bz = np.moveaxis(np.asarray(b_wxyz, dtype=float), -1, 0)
    return np.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        axis=-1,
    )


def rot_z(angle_rad: np.ndarray | float) -> np.ndarray:
    """Rotations (..., 3, 3) about z by `angle_rad` (counter-clockwise seen from above)."""
    a = np.asarray(angle_rad, dtype=float)
    c, s = np.cos(a), np.sin(a)
    zero, one = np.zeros_like(a), np.ones_like(a)
    return np.stack(
        [np.stack([c, -s, zero], -1), np.stack([s, c, zero], -1), np.stack([zero, zero, one], -1)], -2
    )


def yaw_of(R: np.ndarray) -> np.ndarray:
    """Heading (radians, from global x towards y) of the ego x axis of rotations (..., 3, 3)."""
    m = np.asarray(R, dtype=float)
    return np.arctan2(m[..., 1, 0], m[..., 0, 0])


def _time_derivative(values: np.ndarray, times_s: np.ndarray) -> np.ndarray:
    """Derivative of rows `values` (N, k) over `times_s` (central differences, second order at the ends)."""
    edge: Literal[1, 2] = 2 if len(times_s) > 2 else 1
    return np.gradient(values, times_s, axis=0, edge_order=edge)


@dataclass(frozen=True)
class TrueMotion:
    """Ground-truth ego motion of one clip, sampled densely (e.g. 100 Hz)."""

    times_us: np.ndarray
    """(N,) int64 timestamps in microseconds, strictly increasing, N >= 2."""
    global_from_ego_R: np.ndarray
    """(N, 3, 3) rotation of the ego frame in the global frame."""
    global_from_ego_t: np.ndarray
    """(N, 3) position of the ego origin (ground under the rear axle centre), global metres."""

    def __post_init__(self) -> None:
        times = np.asarray(self.times_us)
        R = np.asarray(self.global_from_ego_R, dtype=float)
        t = np.asarray(self.global_from_ego_t, dtype=float)
        if times.ndim != 1 or times.shape[0] < 2 or not np.issubdtype(times.dtype, np.integer):
            raise ValueError(
                f"TrueMotion.times_us must be a 1-D integer array of >= 2 samples, got {times.shape}"
            )
        if np.any(np.diff(times) <= 0):
            raise ValueError("TrueMotion.times_us must be strictly increasing")
        n = times.shape[0]
        if R.shape != (n, 3, 3) or not np.all(np.isfinite(R)):
            raise ValueError(
                f"TrueMotion.global_from_ego_R must be finite with shape ({n}, 3, 3), got {R.shape}"
            )
        if t.shape != (n, 3) or not np.all(np.isfinite(t)):
            raise ValueError(
                f"TrueMotion.global_from_ego_t must be finite with shape ({n}, 3), got {t.shape}"
            )
        ortho = np.abs(np.swapaxes(R, 1, 2) @ R - np.eye(3)).max()
        if ortho > 1e-6 or np.any(np.linalg.det(R) < 0):
            raise ValueError(
                f"TrueMotion.global_from_ego_R must hold rotations (orthonormality error {ortho:.2g})"
            )
        object.__setattr__(self, "times_us", times.astype(np.int64))
        object.__setattr__(self, "global_from_ego_R", R)
        object.__setattr__(self, "global_from_ego_t", t)

    @property
    def times_s(self) -> np.ndarray:
        """(N,) seconds since the first sample (float, avoids precision loss of absolute times)."""
        return (self.times_us - self.times_us[0]) * 1e-6

    @property
    def duration_s(self) -> float:
        """Length of the clip in seconds."""
        return float(self.times_s[-1])

    @cached_property
    def velocity_global(self) -> np.ndarray:
        """(N, 3) velocity of the ego origin in the global frame (central differences), m/s."""
        return _time_derivative(self.global_from_ego_t, self.times_s)

    @cached_property
    def accel_global(self) -> np.ndarray:
        """(N, 3) acceleration of the ego origin in the global frame (differences of the velocity), m/s^2."""
        return _time_derivative(self.velocity_global, self.times_s)

    @cached_property
    def velocity_ego(self) -> np.ndarray:
        """(N, 3) velocity of the ego origin expressed in the ego frame (x forward), m/s."""
        return np.einsum("nji,nj->ni", self.global_from_ego_R, self.velocity_global)

    @cached_property
    def angular_rate_ego(self) -> np.ndarray:
        """(N, 3) angular rate in the ego frame (what a gyro measures), rad/s, from SO(3) log differences."""
        R, ts = self.global_from_ego_R, self.times_s
        prev = np.concatenate([[0], np.arange(len(ts) - 1)])
        nxt = np.concatenate([np.arange(1, len(ts)), [len(ts) - 1]])
        delta = so3_log(np.swapaxes(R[prev], 1, 2) @ R[nxt])
        return delta / (ts[nxt] - ts[prev])[:, None]

    @property
    def speed(self) -> np.ndarray:
        """(N,) speed of the ego origin, m/s."""
        return np.linalg.norm(self.velocity_global, axis=1)

    def interpolate(self, times_us: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Poses (R (M, 3, 3), t (M, 3)) at `times_us`: linear in position, SLERP in rotation."""
        q = np.atleast_1d(np.asarray(times_us, dtype=np.int64))
        lo, hi = int(self.times_us[0]), int(self.times_us[-1])
        if q.size and (q.min() < lo or q.max() > hi):
            raise ValueError(
                f"interpolate: times {q.min()}..{q.max()} us fall outside the motion's {lo}..{hi} us"
            )
        i = np.clip(np.searchsorted(self.times_us, q, side="right") - 1, 0, len(self.times_us) - 2)
        alpha = ((q - self.times_us[i]) / (self.times_us[i + 1] - self.times_us[i]))[:, None]
        t = (1.0 - alpha) * self.global_from_ego_t[i] + alpha * self.global_from_ego_t[i + 1]
        R0, R1 = self.global_from_ego_R[i], self.global_from_ego_R[i + 1]
        R = R0 @ so3_exp(alpha * so3_log(np.swapaxes(R0, 1, 2) @ R1))
        return R, t

    def interpolate_rows(self, values: np.ndarray, times_us: np.ndarray) -> np.ndarray:
        """Linear interpolation of per-sample rows `values` (N, k) at `times_us` (constant past the ends)."""
        q = np.asarray(times_us, dtype=float)
        base = np.asarray(self.times_us - self.times_us[0], dtype=float)
        x = q - float(self.times_us[0])
        return np.stack([np.interp(x, base, values[:, k]) for k in range(values.shape[1])], axis=1)
