"""Configuration of the WIGO pose-graph fusion: sensor noise figures, robust GNSS kernel, node spacing."""

import math
from dataclasses import asdict, dataclass, fields
from typing import Any, Literal, get_args

RobustKernel = Literal["huber", "cauchy", "none"]
WithoutWheels = Literal["logged_pose", "refuse"]


@dataclass(frozen=True)
class WigoConfig:
    """How wheel, IMU, GNSS (and the logged ego pose) are weighted in the pose graph of one clip.

    The defaults describe an automotive-grade sensor set (the synthetic generator's figures are of this
    grade); they are the fusion's assumptions, never read from the generator.
    """

    node_rate_hz: float = 10.0
    """Pose-graph nodes per second (GNSS fix times are added as nodes too)."""
    integration_rate_hz: float = 200.0
    """Step rate of the wheel + gyro dead reckoning between nodes."""
    margin_s: float = 0.5
    """The graph spans the camera timestamps plus this much on both sides (within the sensor data), so
    that GNSS fixes just outside a short clip still count."""
    wheel_track_m: float = 1.5
    """Distance between the rear wheels (yaw rate from the wheels when there is no IMU)."""
    wheel_speed_sigma_mps: float = 0.05
    """White error of the rear-axle speed (mean of the two rear wheels)."""
    wheel_scale_sigma: float = 0.005
    """Relative error of the wheel odometry's distance (tyre radius), charged to every edge."""
    lateral_slip_sigma_mps: float = 0.05
    """Allowed sideways / vertical velocity of the body (the non-holonomic assumption's error)."""
    gyro_noise_rad_s_rthz: float = 3.0e-4
    """Gyro white noise density."""
    gyro_bias_rad_s: float = 5.0e-4
    """Uncompensated gyro bias, charged to every edge as rate error."""
    no_imu_yaw_rate_sigma_rad_s: float = 0.01
    """Yaw-rate error when the yaw rate comes from the rear-wheel speed difference (no IMU)."""
    gravity_sigma_rad: float = 0.005
    """1-sigma of the roll / pitch measured from the motion-compensated accelerometer."""
    gravity_window_s: float = 0.2
    """Accelerometer samples within this window around a node are averaged for its gravity factor."""
    gnss_sigma_floor_m: float = 0.3
    """Lower bound of a GNSS fix's sigma, whatever `std_m` reports."""
    gnss_robust: RobustKernel = "huber"
    """Robust kernel of the GNSS factors, so outliers and jumps after dropouts do not pull the graph."""
    gnss_robust_k: float = 3.0
    """Kernel width in sigmas of the whole 3-D whitened residual (a 3-D Gaussian residual stays below 3.0
    97 % of the time, so ordinary fixes keep full weight and jumps of several sigmas lose it)."""
    ahrs_yaw_sigma_deg: float = 0.3
    """Heading prior from the IMU's own attitude estimate (`ms_imu.q`) at the first node; <= 0 disables."""
    logged_pose_sigmas: tuple[float, float, float, float] = (0.3, 0.1, 2.0, 1.0)
    """(horizontal m, vertical m, heading deg, roll/pitch deg) of the logged `ego_pose` as an input. Its
    errors are slow drifts (lateral wander, a calibration yaw, a sync offset), so the sigmas are spread over
    `logged_pose_correlation_s`; heading is loose because the IMU and GNSS track know it better. A value
    <= 0 leaves that component free; all <= 0 leaves the logged pose out, which a clip without GNSS cannot
    afford (it is then refused: nothing else ties it to the global frame)."""
    free_flat_logged_height: bool = True
    """A clip whose logged ego poses all have z exactly 0 logged no height: nuScenes' localization is 2D ("z is
    always 0", its schema says), so a road that climbs would be pulled flat by the vertical sigma above. Such a
    clip's logged pose then constrains horizontal position, heading and tilt only, and its heights come from the
    wheels and the IMU (the report's `logged_pose_height`). False: z = 0 is fused as a height like any other."""
    without_wheels: WithoutWheels = "logged_pose"
    """What a clip without wheel speeds gets (nuScenes' CAN bus expansion leaves some scenes out and the devkit
    lists others as faulty): `logged_pose`, its logged ego poses as they are, with the sigmas above as their
    covariance (`cama_pipeline.wigo.logged_only`; the report's `odometry` says so), or `refuse`, an error naming
    the scene. Without wheels there is no odometry scale to fuse."""
    logged_pose_correlation_s: float = 8.0
    """Correlation time of the logged pose's errors: its factors count as one measurement per this long."""
    max_iterations: int = 100
    """Levenberg-Marquardt iteration cap."""
    stationary_speed_mps: float = 0.05
    """Wheel speeds below this count as standing still."""

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name in _CHOICES:
                choices = get_args(_CHOICES[f.name])
                if value not in choices:
                    allowed = f"{', '.join(choices[:-1])} or {choices[-1]}"
                    raise ValueError(f"WigoConfig.{f.name} must be {allowed}, got {value!r}")
                continue
            if f.name == "free_flat_logged_height":
                if not isinstance(value, bool):
                    raise ValueError(
                        f"WigoConfig.free_flat_logged_height must be true or false, got {value!r}"
                    )
                continue
            items = value if isinstance(value, tuple) else (value,)
            if not all(isinstance(v, int | float) and not isinstance(v, bool) for v in items) or not all(
                math.isfinite(v) for v in items
            ):
                raise ValueError(f"WigoConfig.{f.name} must be finite number(s), got {value!r}")
        for name in _POSITIVE:
            if getattr(self, name) <= 0:
                raise ValueError(f"WigoConfig.{name} must be > 0, got {getattr(self, name)!r}")
        if self.margin_s < 0:
            raise ValueError(f"WigoConfig.margin_s must be >= 0, got {self.margin_s!r}")
        if len(self.logged_pose_sigmas) != 4:
            raise ValueError("WigoConfig.logged_pose_sigmas must be (horizontal, vertical, heading, tilt)")
        if self.integration_rate_hz < self.node_rate_hz:
            raise ValueError("WigoConfig.integration_rate_hz must be >= node_rate_hz")

    @property
    def uses_logged_pose(self) -> bool:
        """Whether the logged ego pose enters the graph as factors."""
        return any(s > 0 for s in self.logged_pose_sigmas)

    def to_json(self) -> dict[str, Any]:
        """Plain JSON values (tuples as lists), for output files and fingerprints."""
        return {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(self).items()}


_CHOICES: dict[str, Any] = {"gnss_robust": RobustKernel, "without_wheels": WithoutWheels}
"""The fields that take one of a Literal's values."""

_POSITIVE: tuple[str, ...] = (
    "node_rate_hz",
    "integration_rate_hz",
    "wheel_track_m",
    "wheel_speed_sigma_mps",
    "wheel_scale_sigma",
    "lateral_slip_sigma_mps",
    "gyro_noise_rad_s_rthz",
    "gyro_bias_rad_s",
    "no_imu_yaw_rate_sigma_rad_s",
    "gravity_sigma_rad",
    "gravity_window_s",
    "gnss_sigma_floor_m",
    "gnss_robust_k",
    "logged_pose_correlation_s",
    "max_iterations",
    "stationary_speed_mps",
)
