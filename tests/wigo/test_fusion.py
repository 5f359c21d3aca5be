"""WIGO fusion on simulated clips: accuracy against the truth, robustness to GNSS outliers, degraded inputs."""

import logging
from dataclasses import replace

import numpy as np
import pytest

from cama_pipeline.data import GnssSeries, ImuSeries, WheelSeries
from cama_pipeline.synthetic.sensors import SensorNoiseConfig
from cama_pipeline.wigo import WigoConfig, checked_inputs, fuse_clip
from cama_pipeline.wigo.fusion import NoGlobalConstraint, graph_span
from cama_pipeline.wigo.odometry import dead_reckon, integration_grid
from tests.wigo.wigo_sim_inputs import drive, heading_rmse_deg, position_rmse, simulate, with_gnss_jumps

GNSS_ONLY = WigoConfig(logged_pose_sigmas=(0.0, 0.0, 0.0, 0.0))
"""Wheel + IMU + GNSS without the logged pose, so GNSS effects are not masked."""


@pytest.fixture(scope="module")
def clip():
    return simulate(drive(straight_s=10.0, turn_s=6.0))


def test_wigo_beats_the_logged_pose_and_dead_reckoning(clip) -> None:
    fused = fuse_clip(clip.inputs, WigoConfig())
    cam = clip.inputs.cameras
    assert fused.tokens == cam.tokens
    wigo_pos = position_rmse(fused.rotation, fused.translation, clip)
    coarse_pos = position_rmse(cam.rotation, cam.translation, clip)
    assert wigo_pos < 0.8 * coarse_pos
    assert heading_rmse_deg(fused.rotation, clip) < 0.5 * heading_rmse_deg(cam.rotation, clip)
    # dead reckoning alone, started at the true first pose, drifts further than WIGO's whole error
    start, stop = graph_span(clip.inputs, WigoConfig())
    odo = dead_reckon(clip.inputs, integration_grid(start, stop, cam.times_us, 200.0), WigoConfig())
    i0 = int(np.searchsorted(odo.times_us, cam.times_us[-1]))
    i_first = int(np.searchsorted(odo.times_us, cam.times_us[0]))
    travelled = clip.true_rotation[0] @ (
        odo.rotation[i_first].T @ (odo.translation[i0] - odo.translation[i_first])
    )
    drift = np.linalg.norm(clip.true_translation[0] + travelled - clip.true_translation[-1])
    end_error = np.linalg.norm(fused.translation[-1] - clip.true_translation[-1])
    assert end_error < 0.5 and end_error < drift + 0.3


def test_covariances_are_symmetric_positive_and_grow_without_gnss(clip) -> None:
    fused = fuse_clip(clip.inputs, GNSS_ONLY)
    cov = fused.covariance
    assert np.all(np.isfinite(cov))
    assert np.allclose(cov, np.swapaxes(cov, 1, 2), atol=1e-9)
    assert np.all(np.linalg.eigvalsh(cov) > 0)
    gnss = clip.inputs.gnss
    sparse = GnssSeries(gnss.utime[::5], gnss.pos_m[::5], gnss.std_m[::5], gnss.fix[::5])
    fewer = fuse_clip(replace(clip.inputs, gnss=sparse), GNSS_ONLY)
    assert (
        np.trace(fewer.covariance[:, 3:, 3:], axis1=1, axis2=2).mean()
        > np.trace(cov[:, 3:, 3:], axis1=1, axis2=2).mean()
    )


def test_robust_kernel_resists_gnss_outliers(clip) -> None:
    # 15 % of the fixes jump 15 m the same way: the worst case for a convex kernel
    bad = with_gnss_jumps(clip, fraction=0.15, jump_m=15.0)
    plain = fuse_clip(bad.inputs, replace(GNSS_ONLY, gnss_robust="none"))
    plain_error = position_rmse(plain.rotation, plain.translation, clip)
    assert plain_error > 1.5
    for kernel, bound_m in (("huber", 0.8), ("cauchy", 0.5)):
        robust = fuse_clip(bad.inputs, replace(GNSS_ONLY, gnss_robust=kernel))
        error = position_rmse(robust.rotation, robust.translation, clip)
        assert error < bound_m and error < 0.4 * plain_error
        assert robust.report["gnss_downweighted"] >= 5


def test_no_gnss_falls_back_to_the_logged_pose(clip, caplog: pytest.LogCaptureFixture) -> None:
    with caplog.at_level(logging.WARNING):
        inputs = checked_inputs(replace(clip.inputs, gnss=None))
    assert "no GNSS" in caplog.text
    fused = fuse_clip(inputs, WigoConfig())
    assert any("no GNSS" in d for d in fused.report["degraded"])
    assert fused.report["global_constraint"] == "logged_pose"
    assert fused.report["logged_pose_factors"] > 10
    assert position_rmse(fused.rotation, fused.translation, clip) < 1.0
    # anchored, not floating: the position sigma is the logged pose's, at the start and at the end
    assert np.sqrt(fused.covariance[[0, -1], 3, 3]).max() < 1.0


def test_no_gnss_and_no_logged_pose_is_refused_naming_the_scene(clip) -> None:
    inputs = checked_inputs(replace(clip.inputs, gnss=None))
    with pytest.raises(NoGlobalConstraint, match=f"scene '{clip.inputs.scene}'.*no GNSS.*--no-logged-pose"):
        fuse_clip(inputs, GNSS_ONLY)


def test_the_report_names_the_global_constraint(clip) -> None:
    assert fuse_clip(clip.inputs, WigoConfig()).report["global_constraint"] == "gnss+logged_pose"
    assert fuse_clip(clip.inputs, GNSS_ONLY).report["global_constraint"] == "gnss"


def test_empty_gnss_file_counts_as_no_gnss(clip) -> None:
    empty = GnssSeries(np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, bool))
    fused = fuse_clip(checked_inputs(replace(clip.inputs, gnss=empty)), WigoConfig())
    assert any("no GNSS" in d for d in fused.report["degraded"])


def test_no_imu_uses_wheel_yaw_rate(clip) -> None:
    inputs = checked_inputs(replace(clip.inputs, imu=None))
    fused = fuse_clip(inputs, WigoConfig())
    assert any("no IMU" in d for d in fused.report["degraded"])
    # the wheels' radius errors bias the yaw rate: heading is worse than with a gyro, but bounded
    assert position_rmse(fused.rotation, fused.translation, clip) < 0.6
    assert heading_rmse_deg(fused.rotation, clip) < 3.0


def test_no_wheel_speeds_is_refused_naming_the_message(clip) -> None:
    with pytest.raises(ValueError, match="zoe_veh_info"):
        checked_inputs(replace(clip.inputs, wheel=None))


def test_out_of_order_messages_are_sorted_with_a_warning(clip, caplog: pytest.LogCaptureFixture) -> None:
    imu = clip.inputs.imu
    order = np.random.default_rng(1).permutation(len(imu.utime))
    shuffled = ImuSeries(imu.utime[order], imu.linear_accel[order], imu.rotation_rate[order], imu.q[order])
    with caplog.at_level(logging.WARNING):
        inputs = checked_inputs(replace(clip.inputs, imu=shuffled))
    assert "out of time order" in caplog.text
    assert np.array_equal(inputs.imu.utime, imu.utime)
    reference = fuse_clip(checked_inputs(clip.inputs), WigoConfig())
    assert np.allclose(fuse_clip(inputs, WigoConfig()).translation, reference.translation)


def test_repeated_timestamps_are_refused(clip) -> None:
    wheel = clip.inputs.wheel
    utime = wheel.utime.copy()
    utime[10] = utime[9]
    with pytest.raises(ValueError, match=r"zoe_veh_info has two messages with utime"):
        checked_inputs(replace(clip.inputs, wheel=WheelSeries(utime, wheel.speed_rpm)))


def test_camera_times_out_of_order_are_refused(clip) -> None:
    cam = clip.inputs.cameras
    times = cam.times_us.copy()
    times[[3, 4]] = times[[4, 3]]
    with pytest.raises(ValueError, match="camera timestamps are not in time order"):
        checked_inputs(replace(clip.inputs, cameras=replace(cam, times_us=times)))


def test_one_frame_clip_gives_one_pose(clip) -> None:
    cam = clip.inputs.cameras
    k = len(cam.times_us) // 2
    one = replace(
        cam,
        tokens=cam.tokens[k : k + 1],
        channels=cam.channels[k : k + 1],
        times_us=cam.times_us[k : k + 1],
        rotation=cam.rotation[k : k + 1],
        translation=cam.translation[k : k + 1],
    )
    fused = fuse_clip(checked_inputs(replace(clip.inputs, cameras=one)), WigoConfig())
    assert fused.translation.shape == (1, 3)
    assert np.linalg.norm(fused.translation[0] - clip.true_translation[k]) < 1.0
    # the GNSS fixes within the margin still count
    assert fused.report["gnss_factors"] >= 3


def test_stationary_clip_stays_put() -> None:
    clip = simulate(drive(straight_s=4.0, turn_s=0.0, speed_mps=0.0))
    fused = fuse_clip(clip.inputs, WigoConfig())
    spread = np.linalg.norm(fused.translation - fused.translation.mean(axis=0), axis=1).max()
    assert spread < 0.05
    assert position_rmse(fused.rotation, fused.translation, clip) < 1.0


def test_gnss_dropout_is_bridged_by_odometry() -> None:
    sensors = SensorNoiseConfig(gnss_dropout_s=6.0, gnss_outliers=False)
    clip = simulate(drive(straight_s=12.0, turn_s=6.0), sensors=sensors)
    fused = fuse_clip(clip.inputs, GNSS_ONLY)
    error = np.linalg.norm(fused.translation - clip.true_translation, axis=1)
    assert error.max() < 1.0


@pytest.mark.parametrize(
    ("field", "value"),
    [("node_rate_hz", 0.0), ("gnss_robust", "tukey"), ("margin_s", -1.0), ("logged_pose_sigmas", (1.0,))],
)
def test_config_rejects_bad_values_naming_the_field(field: str, value: object) -> None:
    with pytest.raises(ValueError, match=field):
        WigoConfig(**{field: value})
