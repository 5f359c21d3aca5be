"""In-memory WIGO inputs for tests: a flat drive (straight, then a left turn) with the generator's sensor
simulators, so tests control duration, outliers and which sensors exist without writing a data set."""

from dataclasses import dataclass, replace

import numpy as np

from cama_pipeline.data import GnssSeries, ImuSeries, WheelSeries
from cama_pipeline.synthetic.motion import TrueMotion, rot_z
from cama_pipeline.synthetic.sensors import SensorNoiseConfig, coarse_ego_poses, simulate_can
from cama_pipeline.wigo import ClipInputs, LoggedPoses

START_US = 1_600_000_000_000_000
CHANNELS = ("CAM_FRONT", "CAM_BACK")


@dataclass(frozen=True, eq=False)
class SimClip:
    """Inputs of a simulated clip and the truth at its camera times."""

    inputs: ClipInputs
    true_rotation: np.ndarray
    true_translation: np.ndarray


def drive(straight_s: float, turn_s: float, speed_mps: float = 8.0, radius_m: float = 25.0) -> TrueMotion:
    """True motion at 100 Hz: straight east, then a left arc; 0.5 s of margin on both sides."""
    dt = 0.01
    times = np.arange(-0.5, straight_s + turn_s + 0.5 + dt / 2, dt)
    yaw_rate = np.where(times > straight_s, speed_mps / radius_m if speed_mps > 0 else 0.0, 0.0)
    yaw = np.concatenate([[0.0], np.cumsum(yaw_rate[:-1] * dt)]) + 0.3
    step = speed_mps * dt * np.stack([np.cos(yaw), np.sin(yaw)], axis=1)
    xy = np.concatenate([[[0.0, 0.0]], np.cumsum(step[:-1], axis=0)]) + np.array([500.0, 1200.0])
    t = np.column_stack([xy, np.full(len(times), 3.0)])
    return TrueMotion(START_US + np.round(times * 1e6).astype(np.int64), rot_z(yaw), t)


def simulate(
    motion: TrueMotion, *, seed: int = 3, camera_hz: float = 12.0, sensors: SensorNoiseConfig | None = None
) -> SimClip:
    """Camera times (two channels) with coarse poses, and IMU / wheel / GNSS series, as WIGO reads them."""
    cfg = sensors or SensorNoiseConfig()
    rng = np.random.default_rng(seed)
    first, last = int(motion.times_us[0]) + 500_000, int(motion.times_us[-1]) - 500_000
    base = np.arange(first, last, int(1e6 / camera_hz), dtype=np.int64)
    times = np.sort(np.concatenate([base + 12_000, base + 45_500]))
    channels = tuple(CHANNELS[i % 2] for i in range(len(times)))
    coarse_R, coarse_t = coarse_ego_poses(motion, times, cfg, rng)
    can = simulate_can(motion, cfg, rng)
    true_R, true_t = motion.interpolate(times)
    cameras = LoggedPoses(tuple(f"tok{i}" for i in range(len(times))), channels, times, coarse_R, coarse_t)
    imu = ImuSeries(
        utime=[r["utime"] for r in can["ms_imu"]],
        linear_accel=[r["linear_accel"] for r in can["ms_imu"]],
        rotation_rate=[r["rotation_rate"] for r in can["ms_imu"]],
        q=[r["q"] for r in can["ms_imu"]],
    )
    wheel = WheelSeries(
        utime=[r["utime"] for r in can["zoe_veh_info"]],
        speed_rpm=[[r[f"{w}_wheel_speed"] for w in ("FL", "FR", "RL", "RR")] for r in can["zoe_veh_info"]],
    )
    gnss = GnssSeries(
        utime=[r["utime"] for r in can["gnss"]],
        pos_m=[r["pos"] for r in can["gnss"]],
        std_m=[r["std_m"] for r in can["gnss"]],
        fix=[r["fix"] for r in can["gnss"]],
    )
    return SimClip(ClipInputs("sim", cameras, wheel, imu, gnss), true_R, true_t)


def with_gnss_jumps(clip: SimClip, fraction: float, jump_m: float, seed: int = 5) -> SimClip:
    """The clip with `fraction` of its GNSS fixes moved `jump_m` sideways (multipath outliers)."""
    gnss = clip.inputs.gnss
    assert gnss is not None
    rng = np.random.default_rng(seed)
    hit = rng.uniform(size=len(gnss.utime)) < fraction
    pos = np.array(gnss.pos_m)
    pos[hit, 1] += jump_m
    moved = GnssSeries(gnss.utime, pos, gnss.std_m, gnss.fix)
    return replace(clip, inputs=replace(clip.inputs, gnss=moved))


def position_rmse(R: np.ndarray, t: np.ndarray, clip: SimClip) -> float:
    """3-D position RMSE against the truth (R unused, for symmetry with heading_rmse_deg)."""
    del R
    return float(np.sqrt(np.mean(np.sum((t - clip.true_translation) ** 2, axis=1))))


def heading_rmse_deg(R: np.ndarray, clip: SimClip) -> float:
    """Heading RMSE against the truth, degrees."""
    yaw = np.arctan2(R[:, 1, 0], R[:, 0, 0])
    true = np.arctan2(clip.true_rotation[:, 1, 0], clip.true_rotation[:, 0, 0])
    diff = (yaw - true + np.pi) % (2 * np.pi) - np.pi
    return float(np.degrees(np.sqrt(np.mean(diff**2))))
