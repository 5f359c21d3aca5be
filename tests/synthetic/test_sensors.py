"""Tests of the synthetic sensor simulators and the true-motion helpers they build on."""

import json
import math

import numpy as np
import pytest

from cama_pipeline.data.schema import CAN_MESSAGES, GNSS_MESSAGE, IMU_MESSAGE, WHEEL_MESSAGE, WHEEL_RADIUS_M
from cama_pipeline.synthetic.motion import (
    TrueMotion,
    matrix_to_quat,
    quat_multiply,
    quat_to_matrix,
    rot_z,
    so3_exp,
    so3_log,
    yaw_of,
)
from cama_pipeline.synthetic.sensors import (
    SensorNoiseConfig,
    coarse_ego_poses,
    sample_times_us,
    simulate_can,
    simulate_gnss,
    simulate_imu,
    simulate_wheels,
)

T0_US = 1_532_402_927_647_951
"""A nuScenes-like absolute start time, so nothing assumes clips start at 0."""


def _rot_y(angle_rad: float) -> np.ndarray:
    """Rotation about y (positive pitches the x axis down)."""
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _times(duration_s: float, rate_hz: float = 100.0) -> tuple[np.ndarray, np.ndarray]:
    """Absolute microsecond times and seconds from the start."""
    n = int(round(duration_s * rate_hz)) + 1
    times_us = T0_US + np.arange(n, dtype=np.int64) * int(1e6 / rate_hz)
    return times_us, (times_us - T0_US) * 1e-6


def straight_drive(
    duration_s: float = 30.0, v0: float = 0.0, accel: float = 0.5, yaw_deg: float = 30.0
) -> TrueMotion:
    """Level straight drive along heading `yaw_deg`, accelerating from `v0`."""
    times_us, s = _times(duration_s)
    heading = np.array([math.cos(math.radians(yaw_deg)), math.sin(math.radians(yaw_deg)), 0.0])
    dist = v0 * s + 0.5 * accel * s**2
    R = np.repeat(rot_z(math.radians(yaw_deg))[None], len(s), axis=0)
    return TrueMotion(times_us, R, np.array([400.0, 1100.0, 3.0]) + dist[:, None] * heading)


def slope_turn(
    duration_s: float = 20.0, radius: float = 30.0, speed: float = 8.0, grade: float = 0.05
) -> TrueMotion:
    """Constant-radius left turn climbing a constant grade (a helix), nose up along the slope."""
    times_us, s = _times(duration_s)
    psi = speed * s / radius
    pos = np.stack([radius * np.sin(psi), radius * (1 - np.cos(psi)), grade * speed * s], axis=1)
    R = rot_z(psi) @ _rot_y(-math.atan(grade))
    return TrueMotion(times_us, R, pos + np.array([380.0, 1050.0, 1.0]))


def stationary(duration_s: float = 10.0) -> TrueMotion:
    """A car standing still on level ground."""
    times_us, s = _times(duration_s)
    R = np.repeat(rot_z(1.1)[None], len(s), axis=0)
    return TrueMotion(times_us, R, np.tile([410.0, 1090.0, 2.0], (len(s), 1)))


@pytest.fixture(scope="module")
def drive() -> TrueMotion:
    return straight_drive()


@pytest.fixture(scope="module")
def turn() -> TrueMotion:
    return slope_turn()


@pytest.fixture(scope="module")
def still() -> TrueMotion:
    return stationary()


def _column(records: list[dict], key: str) -> np.ndarray:
    return np.array([r[key] for r in records], dtype=float)


def _wheels_mps(records: list[dict]) -> np.ndarray:
    """(n, 4) FL, FR, RL, RR wheel speeds in m/s with the nominal radius."""
    rpm = np.stack([_column(records, f"{w}_wheel_speed") for w in ("FL", "FR", "RL", "RR")], axis=1)
    return rpm * 2 * math.pi * WHEEL_RADIUS_M / 60.0


# --- motion -------------------------------------------------------------------------------------------------


def test_so3_helpers_round_trip() -> None:
    rng = np.random.default_rng(0)
    rotvec = rng.normal(size=(50, 3))
    rotvec *= (rng.uniform(0, 3.0, 50) / np.linalg.norm(rotvec, axis=1))[:, None]
    R = so3_exp(rotvec)
    np.testing.assert_allclose(so3_log(R), rotvec, atol=1e-9)
    q = matrix_to_quat(R)
    assert np.all(q[:, 0] >= 0)
    np.testing.assert_allclose(quat_to_matrix(q), R, atol=1e-12)
    np.testing.assert_allclose(quat_to_matrix(np.array([1.0, 0, 0, 0])), np.eye(3))
    q90 = matrix_to_quat(rot_z(math.pi / 2))
    np.testing.assert_allclose(q90, [math.sqrt(0.5), 0, 0, math.sqrt(0.5)], atol=1e-12)
    np.testing.assert_allclose(quat_to_matrix(quat_multiply(q[0], q[1])), R[0] @ R[1], atol=1e-12)


def test_interpolate_matches_samples_and_slerps() -> None:
    times = np.array([T0_US, T0_US + 1_000_000], dtype=np.int64)
    R = np.stack([np.eye(3), rot_z(math.pi / 2)])
    t = np.array([[0.0, 0.0, 0.0], [10.0, 2.0, -1.0]])
    motion = TrueMotion(times, R, t)
    R_q, t_q = motion.interpolate(np.array([T0_US, T0_US + 250_000, T0_US + 500_000, T0_US + 1_000_000]))
    np.testing.assert_allclose(R_q[[0, 3]], R, atol=1e-12)
    np.testing.assert_allclose(t_q[[0, 3]], t, atol=1e-12)
    np.testing.assert_allclose(R_q[1], rot_z(math.pi / 8), atol=1e-12)
    np.testing.assert_allclose(R_q[2], rot_z(math.pi / 4), atol=1e-12)
    np.testing.assert_allclose(t_q[2], [5.0, 1.0, -0.5])
    with pytest.raises(ValueError, match="outside"):
        motion.interpolate(np.array([T0_US - 1]))
    with pytest.raises(ValueError, match="outside"):
        motion.interpolate(np.array([T0_US + 1_000_001]))


def test_interpolate_dense_motion(turn: TrueMotion) -> None:
    R_q, t_q = turn.interpolate(turn.times_us[::7])
    np.testing.assert_allclose(R_q, turn.global_from_ego_R[::7], atol=1e-12)
    np.testing.assert_allclose(t_q, turn.global_from_ego_t[::7], atol=1e-9)


def test_true_motion_rejects_bad_input() -> None:
    times = np.array([T0_US, T0_US + 10, T0_US + 5], dtype=np.int64)
    R = np.repeat(np.eye(3)[None], 3, axis=0)
    with pytest.raises(ValueError, match="increasing"):
        TrueMotion(times, R, np.zeros((3, 3)))
    with pytest.raises(ValueError, match="global_from_ego_t"):
        TrueMotion(np.sort(times), R, np.zeros((2, 3)))
    with pytest.raises(ValueError, match="rotations"):
        TrueMotion(np.sort(times), R * 2.0, np.zeros((3, 3)))


def test_motion_derivatives(drive: TrueMotion, turn: TrueMotion) -> None:
    s = drive.times_s
    np.testing.assert_allclose(drive.speed, 0.5 * s, atol=1e-6)
    np.testing.assert_allclose(drive.velocity_ego[:, 0], 0.5 * s, atol=1e-6)
    np.testing.assert_allclose(np.linalg.norm(drive.accel_global, axis=1), 0.5, atol=1e-6)
    np.testing.assert_allclose(drive.angular_rate_ego, 0.0, atol=1e-12)
    yaw_rate, pitch = 8.0 / 30.0, math.atan(0.05)
    expected = [yaw_rate * math.sin(pitch), 0.0, yaw_rate * math.cos(pitch)]
    np.testing.assert_allclose(turn.angular_rate_ego, np.tile(expected, (len(turn.times_us), 1)), atol=1e-9)
    np.testing.assert_allclose(turn.velocity_ego[1:-1, 1:], 0.0, atol=1e-3)


# --- IMU ----------------------------------------------------------------------------------------------------


def test_imu_stationary_level_reads_gravity(still: TrueMotion) -> None:
    records = simulate_imu(still, SensorNoiseConfig(), np.random.default_rng(1))
    assert len(records) == len(still.times_us)
    assert all(set(r) == set(CAN_MESSAGES[IMU_MESSAGE]) for r in records)
    np.testing.assert_allclose(_column(records, "linear_accel").mean(axis=0), [0, 0, 9.81], atol=0.1)
    np.testing.assert_allclose(_column(records, "rotation_rate").mean(axis=0), 0.0, atol=2e-3)
    np.testing.assert_allclose(
        quat_to_matrix(np.array(records[0]["q"])), still.global_from_ego_R[0], atol=1e-12
    )


def test_imu_straight_drive_specific_force(drive: TrueMotion) -> None:
    force = _column(simulate_imu(drive, SensorNoiseConfig(), np.random.default_rng(2)), "linear_accel")
    np.testing.assert_allclose(force[100:-100].mean(axis=0), [0.5, 0.0, 9.81], atol=0.1)


def test_imu_gyro_and_drifting_attitude(turn: TrueMotion) -> None:
    cfg = SensorNoiseConfig()
    records = simulate_imu(turn, cfg, np.random.default_rng(3))
    gyro = _column(records, "rotation_rate")
    assert gyro[:, 2].mean() == pytest.approx(turn.angular_rate_ego[:, 2].mean(), abs=2e-3)
    assert gyro[:, 2].mean() == pytest.approx(8.0 / 30.0 * math.cos(math.atan(0.05)), abs=2e-3)
    q = np.array([r["q"] for r in records])
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-12)
    yaw_error = np.degrees(
        np.angle(np.exp(1j * (yaw_of(quat_to_matrix(q)) - yaw_of(turn.global_from_ego_R))))
    )
    assert abs(yaw_error[0]) < 1e-9
    assert 1e-3 < abs(yaw_error[-1]) < 2.0


# --- wheels -------------------------------------------------------------------------------------------------


def test_wheels_integrate_to_travelled_distance(drive: TrueMotion) -> None:
    records = simulate_wheels(drive, SensorNoiseConfig(), np.random.default_rng(4))
    assert all(set(r) == set(CAN_MESSAGES[WHEEL_MESSAGE]) for r in records)
    speeds = _wheels_mps(records)
    assert np.all(speeds >= 0.0)
    assert np.all(speeds[0] == 0.0)
    distance = np.trapezoid(speeds.mean(axis=1), _column(records, "utime") * 1e-6)
    true_distance = np.linalg.norm(drive.global_from_ego_t[-1] - drive.global_from_ego_t[0])
    assert distance == pytest.approx(true_distance, rel=0.015)


def test_wheels_in_left_turn_outer_right_wheels_faster(turn: TrueMotion) -> None:
    cfg = SensorNoiseConfig()
    speeds = _wheels_mps(simulate_wheels(turn, cfg, np.random.default_rng(5)))
    fl, fr, rl, rr = speeds.mean(axis=0)
    assert fr > fl and rr > rl  # the left wheels are on the inside of a left turn
    assert fl > rl and fr > rr  # the steered front wheels run on larger circles
    wheel_yaw_rate = (rr - rl) / cfg.wheel_track_m
    assert wheel_yaw_rate == pytest.approx(turn.angular_rate_ego[:, 2].mean(), rel=0.2)


def test_wheels_stationary_read_zero(still: TrueMotion) -> None:
    assert np.all(_wheels_mps(simulate_wheels(still, SensorNoiseConfig(), np.random.default_rng(6))) == 0.0)


# --- GNSS ---------------------------------------------------------------------------------------------------


def _gnss_errors(motion: TrueMotion, records: list[dict]) -> np.ndarray:
    times = np.array([r["utime"] for r in records], dtype=np.int64)
    _, truth = motion.interpolate(times)
    return _column(records, "pos") - truth


def test_gnss_noise_outliers_and_dropout() -> None:
    motion = straight_drive(duration_s=120.0, accel=0.1)
    cfg = SensorNoiseConfig()
    records = simulate_gnss(motion, cfg, np.random.default_rng(7))
    assert all(set(r) == set(CAN_MESSAGES[GNSS_MESSAGE]) for r in records)
    errors = _gnss_errors(motion, records)
    fix = np.array([r["fix"] for r in records])
    outlier = np.linalg.norm(errors[:, :2], axis=1) > 4.5
    assert 2 <= outlier.sum() <= 0.05 * len(records)
    clean = errors[~outlier & fix]
    np.testing.assert_allclose(clean.std(axis=0), [1.0, 1.0, 2.0], rtol=0.15)
    np.testing.assert_allclose(clean.mean(axis=0), 0.0, atol=0.3)
    gaps = np.diff([r["utime"] for r in records]) * 1e-6
    assert np.sum(gaps > 0.3) == 1 and gaps.max() == pytest.approx(cfg.gnss_dropout_s, abs=0.25)
    after = int(np.argmax(gaps)) + 1
    assert not fix[after] and records[after]["std_m"] == [3.0, 3.0, 6.0]
    assert fix.sum() == len(records) - 5
    no_outliers = simulate_gnss(motion, SensorNoiseConfig(gnss_outliers=False), np.random.default_rng(7))
    assert np.linalg.norm(_gnss_errors(motion, no_outliers)[:, :2], axis=1).max() < 4.5 * 3
    assert np.linalg.norm(_gnss_errors(motion, no_outliers)[fix, :2], axis=1).max() < 4.5


def test_gnss_without_dropout_keeps_every_fix(turn: TrueMotion) -> None:
    records = simulate_gnss(turn, SensorNoiseConfig(gnss_dropout_s=0.0), np.random.default_rng(8))
    assert len(records) == len(sample_times_us(turn, 5.0)) and all(r["fix"] for r in records)


def test_gnss_dropout_fits_short_clip() -> None:
    motion = straight_drive(duration_s=2.5, v0=5.0)
    records = simulate_gnss(motion, SensorNoiseConfig(), np.random.default_rng(8))
    assert 6 <= len(records) <= 10
    assert records[0]["utime"] >= motion.times_us[0] and records[-1]["utime"] <= motion.times_us[-1]


# --- coarse ego poses ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", ["drive", "turn", "still"])
def test_coarse_poses_have_smooth_bounded_errors(name: str, request: pytest.FixtureRequest) -> None:
    motion: TrueMotion = request.getfixturevalue(name)
    times = motion.times_us[::2]
    R_c, t_c = coarse_ego_poses(motion, times, SensorNoiseConfig(), np.random.default_rng(9))
    R, t = motion.interpolate(times)
    position_error = t_c - t
    error_m = np.linalg.norm(position_error, axis=1)
    heading_error = np.degrees(np.linalg.norm(so3_log(np.swapaxes(R, 1, 2) @ R_c), axis=1))
    assert error_m.min() > 0.02 and error_m.max() < 2.5
    assert heading_error.min() > 1e-6 and 0.1 < heading_error.max() < 1.0
    step_m = np.linalg.norm(np.diff(position_error, axis=0), axis=1)
    assert step_m.max() < 0.005  # 20 ms apart: smooth drift, no jitter
    assert np.abs(np.diff(position_error, n=2, axis=0)).max() < 5e-4


def test_coarse_poses_same_times_same_errors_regardless_of_query(drive: TrueMotion) -> None:
    cfg = SensorNoiseConfig()
    R_a, t_a = coarse_ego_poses(drive, drive.times_us, cfg, np.random.default_rng(10))
    R_b, t_b = coarse_ego_poses(drive, drive.times_us[::50], cfg, np.random.default_rng(10))
    np.testing.assert_allclose(t_a[::50], t_b, atol=1e-9)
    np.testing.assert_allclose(R_a[::50], R_b, atol=1e-12)
    with pytest.raises(ValueError, match="outside"):
        coarse_ego_poses(drive, np.array([drive.times_us[-1] + 1]), cfg, np.random.default_rng(10))


# --- whole CAN output, determinism, config ------------------------------------------------------------------


def test_same_seed_same_output_and_json_ready(turn: TrueMotion) -> None:
    cfg = SensorNoiseConfig()
    first = simulate_can(turn, cfg, np.random.default_rng(11))
    second = simulate_can(turn, cfg, np.random.default_rng(11))
    other = simulate_can(turn, cfg, np.random.default_rng(12))
    assert set(first) == set(CAN_MESSAGES)
    assert json.dumps(first) == json.dumps(second) != json.dumps(other)
    for records in first.values():
        assert all(type(r["utime"]) is int for r in records)
    imu = first[IMU_MESSAGE][0]
    assert all(type(v) is float for v in imu["linear_accel"] + imu["q"])
    assert type(first[GNSS_MESSAGE][0]["fix"]) is bool


def test_sample_times_stay_inside_clip(turn: TrueMotion) -> None:
    times = sample_times_us(turn, 3.0)
    assert times[0] == turn.times_us[0] and times[-1] <= turn.times_us[-1] and len(times) == 61
    assert np.all(np.diff(times) > 0)


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("gyro_bias_sigma_rad_s", -1e-4),
        ("imu_rate_hz", 0.0),
        ("gnss_outlier_prob", 1.5),
        ("gnss_outlier_jump_m", (20.0, 5.0)),
        ("pose_lever_arm_m", (0.1, 0.0)),
        ("wheel_track_m", float("nan")),
        ("gnss_outliers", "yes"),
        ("pose_sync_offset_s", 2.0),
    ],
)
def test_bad_config_names_the_field(field: str, value: object) -> None:
    with pytest.raises(ValueError, match=f"SensorNoiseConfig.{field}"):
        SensorNoiseConfig(**{field: value})  # type: ignore[arg-type]
