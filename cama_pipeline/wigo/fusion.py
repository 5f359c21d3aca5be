"""WIGO for one clip: a gtsam pose graph of wheel + IMU steps, gravity, robust GNSS and (optionally) the
logged ego pose, solved by Levenberg-Marquardt; poses and covariances at every camera timestamp.

Nodes sit on a regular grid over the clip (plus one at every GNSS fix time, so fixes need no
interpolation). Each camera pose is the odometry propagated from the two nodes around it, blended on
SE(3) (`Pose3.slerp`), so poses between nodes keep the odometry's fine motion.

Global constraint (what ties the clip to the global frame, named in the report's `global_constraint`): the
GNSS fixes and the logged ego pose (`gnss+logged_pose`, the default), GNSS alone (`gnss`, when the config
leaves the logged pose out), or the logged ego pose alone (`logged_pose`: a clip without GNSS, as every
real nuScenes clip is). A clip without GNSS whose config leaves the logged pose out has none and is refused
(`NoGlobalConstraint`), rather than left floating on its dead reckoning.

Degraded inputs: no IMU -> wheel yaw rate and no gravity factors; a one-image clip -> one node (plus the nodes
of GNSS fixes within `margin_s`), solved all the same.
"""

import logging
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import gtsam
import numpy as np
from gtsam.symbol_shorthand import X

from cama_pipeline.wigo.attitude import gravity_up_body
from cama_pipeline.wigo.config import WigoConfig
from cama_pipeline.wigo.inputs import ClipInputs, LoggedPoses
from cama_pipeline.wigo.odometry import (
    DeadReckoning,
    dead_reckon,
    integration_grid,
    relative_poses,
    step_sigmas,
)

logger = logging.getLogger(__name__)

_UP = gtsam.Unit3(np.array([0.0, 0.0, 1.0]))
_LOOSE_TILT_RAD = 0.5
"""Sigma left on roll and pitch by priors that only mean to fix the heading."""
FREE_SIGMA = 1e3
"""Sigma of a prior component the configuration leaves free."""
FLAT_HEIGHT_GAUGE_SIGMA_M = 1.0
"""Sigma of the one height prior (the first node at the logged z) of a clip whose logged poses carry no height:
it fixes the gauge the free heights leave open, so that the marginal covariances exist."""


FREE_HEIGHT = "free: every logged z is 0 (a 2D localization)"
"""The report's `logged_pose_height` of a clip whose logged poses carry no height."""


def height_is_free(report: Mapping[str, Any]) -> bool:
    """Whether nothing measured a fused clip's height (its report says so): 2D logged poses and no GNSS fix, so
    its height is only where the gauge held it."""
    constraint = str(report.get("global_constraint", ""))
    return report.get("logged_pose_height") == FREE_HEIGHT and "gnss" not in constraint


def logged_pose_sigmas(cameras: LoggedPoses, config: WigoConfig) -> tuple[np.ndarray, bool]:
    """The logged pose's sigmas in gtsam's body tangent order [rx, ry, rz, tx, ty, tz] (a component the config
    leaves free at FREE_SIGMA), and whether the clip's logged z are all 0 with `free_flat_logged_height`: a 2D
    localization (nuScenes'), whose height is then free as well."""
    horizontal, vertical, heading_deg, tilt_deg = config.logged_pose_sigmas
    flat = config.free_flat_logged_height and not np.any(cameras.translation[:, 2])
    sigmas = np.array(
        [math.radians(tilt_deg), math.radians(tilt_deg), math.radians(heading_deg)]
        + [horizontal, horizontal, 0.0 if flat else vertical]
    )
    return np.where(sigmas > 0, sigmas, FREE_SIGMA), flat


class NoGlobalConstraint(ValueError):
    """A clip with neither GNSS fixes nor the logged ego pose to tie it to the global frame."""


@dataclass(frozen=True, eq=False)
class FusedPoses:
    """WIGO's output for one clip: a global_from_ego pose and its covariance per camera image."""

    scene: str
    tokens: tuple[str, ...]
    """sample_data token per image (same order as the inputs' cameras)."""
    channels: tuple[str, ...]
    times_us: np.ndarray
    """(N,) int64 capture times."""
    rotation: np.ndarray
    """(N, 3, 3) global_from_ego rotations."""
    translation: np.ndarray
    """(N, 3) global_from_ego translations, metres."""
    covariance: np.ndarray
    """(N, 6, 6) pose covariance in gtsam's body tangent order [rx, ry, rz, tx, ty, tz]; NaN if unknown."""
    node_times_us: np.ndarray
    """(K,) int64 graph node times."""
    report: dict[str, Any] = field(default_factory=dict)
    """Counts and figures of the solve (nodes, factors, GNSS fixes down-weighted, errors, degradations)."""


def _pose(R: np.ndarray, t: np.ndarray) -> gtsam.Pose3:
    return gtsam.Pose3(gtsam.Rot3(np.asarray(R, dtype=np.float64)), np.asarray(t, dtype=np.float64))


def graph_span(inputs: ClipInputs, config: WigoConfig) -> tuple[int, int]:
    """[start, stop] of the graph: the camera times plus `margin_s`, the margin only where wheels cover it."""
    cam = inputs.cameras.times_us
    margin = int(config.margin_s * 1e6)
    wheel = inputs.wheel.utime
    start = min(int(cam[0]), max(int(cam[0]) - margin, int(wheel[0])))
    stop = max(int(cam[-1]), min(int(cam[-1]) + margin, int(wheel[-1])))
    if cam[0] < wheel[0] - 1e5 or cam[-1] > wheel[-1] + 1e5:
        logger.warning(
            "scene %s: camera times %d..%d us reach beyond the wheel data %d..%d us; speeds held there",
            inputs.scene,
            cam[0],
            cam[-1],
            wheel[0],
            wheel[-1],
        )
    return start, stop


def node_times(inputs: ClipInputs, config: WigoConfig, start: int, stop: int) -> np.ndarray:
    """Regular node grid over [start, stop] plus the GNSS fix times within it."""
    fixes = np.zeros(0, dtype=np.int64)
    if inputs.gnss is not None:
        fixes = inputs.gnss.utime[(inputs.gnss.utime >= start) & (inputs.gnss.utime <= stop)]
    return integration_grid(start, stop, fixes, config.node_rate_hz)


def logged_pose_at(cameras: LoggedPoses, t_us: int) -> gtsam.Pose3:
    """The logged pose at `t_us`, interpolated on SE(3) between camera images (held beyond the ends)."""
    times = cameras.times_us
    j = int(np.clip(np.searchsorted(times, t_us, side="right") - 1, 0, len(times) - 1))
    a = _pose(cameras.rotation[j], cameras.translation[j])
    if j + 1 >= len(times) or t_us <= times[j] or times[j + 1] == times[j]:
        return a
    b = _pose(cameras.rotation[j + 1], cameras.translation[j + 1])
    return a.slerp(float((t_us - times[j]) / (times[j + 1] - times[j])), b)


def _odometry_pose(odometry: DeadReckoning, t_us: int) -> gtsam.Pose3:
    """Dead-reckoned start_from_body at a grid time."""
    i = int(np.searchsorted(odometry.times_us, t_us))
    return _pose(odometry.rotation[i], odometry.translation[i])


def _gnss_noise(sigmas: np.ndarray, config: WigoConfig) -> gtsam.noiseModel.Base:
    base = gtsam.noiseModel.Diagonal.Sigmas(np.maximum(sigmas, config.gnss_sigma_floor_m))
    if config.gnss_robust == "none":
        return base
    kernel = (
        gtsam.noiseModel.mEstimator.Huber.Create(config.gnss_robust_k)
        if config.gnss_robust == "huber"
        else gtsam.noiseModel.mEstimator.Cauchy.Create(config.gnss_robust_k)
    )
    return gtsam.noiseModel.Robust.Create(kernel, base)


class _GraphBuilder:
    """Collects the factors of one clip's pose graph and its initial values."""

    def __init__(self, inputs: ClipInputs, config: WigoConfig, nodes: np.ndarray, odometry: DeadReckoning):
        self.inputs, self.config, self.nodes, self.odometry = inputs, config, nodes, odometry
        self.graph = gtsam.NonlinearFactorGraph()
        self.initial = gtsam.Values()
        self.report: dict[str, Any] = {"nodes": len(nodes), "degraded": []}

    def initial_values(self) -> None:
        """Odometry chain placed in the global frame through the logged pose of the first image."""
        cam = self.inputs.cameras
        t0 = int(cam.times_us[0])
        global_from_start = logged_pose_at(cam, t0).compose(_odometry_pose(self.odometry, t0).inverse())
        for k, t in enumerate(self.nodes):
            self.initial.insert(X(k), global_from_start.compose(_odometry_pose(self.odometry, int(t))))

    def odometry_factors(self) -> None:
        R, t = relative_poses(self.odometry, self.nodes)
        sigmas = step_sigmas(self.odometry, self.nodes, self.config, self.inputs.imu is not None)
        for k in range(len(R)):
            noise = gtsam.noiseModel.Diagonal.Sigmas(sigmas[k])
            self.graph.add(gtsam.BetweenFactorPose3(X(k), X(k + 1), _pose(R[k], t[k]), noise))
        self.report["odometry_factors"] = len(R)

    def gravity_factors(self) -> None:
        up = gravity_up_body(self.inputs, self.odometry, self.nodes, self.config)
        if up is None:
            self.report["degraded"].append("no IMU: yaw rate from the rear wheels, no gravity factors")
            return
        noise = gtsam.noiseModel.Isotropic.Sigma(2, self.config.gravity_sigma_rad)
        for k, vector in enumerate(up):
            self.graph.add(gtsam.AttitudeFactorPose3(X(k), _UP, noise, gtsam.Unit3(vector)))
        self.report["gravity_factors"] = len(up)

    def gnss_factors(self) -> list[tuple[int, np.ndarray, np.ndarray]]:
        """GNSS position factors at their nodes; returns (node, position, sigma) of each for the report."""
        gnss = self.inputs.gnss
        used: list[tuple[int, np.ndarray, np.ndarray]] = []
        if gnss is None:
            self.report["degraded"].append("no GNSS: the logged ego pose is the global constraint")
            return used
        index = {int(t): k for k, t in enumerate(self.nodes)}
        for t, pos, std in zip(gnss.utime, gnss.pos_m, gnss.std_m, strict=True):
            k = index.get(int(t))
            if k is None:
                continue
            self.graph.add(gtsam.GPSFactor(X(k), pos, _gnss_noise(std, self.config)))
            used.append((k, pos, np.maximum(std, self.config.gnss_sigma_floor_m)))
        self.report["gnss_factors"] = len(used)
        return used

    def heading_prior(self) -> None:
        """The IMU's own attitude (ms_imu.q) as a heading prior on the first node."""
        imu, sigma_deg = self.inputs.imu, self.config.ahrs_yaw_sigma_deg
        if imu is None or sigma_deg <= 0:
            return
        j = int(np.argmin(np.abs(imu.utime - self.nodes[0])))
        w, x, y, z = imu.q[j]
        sigmas = np.array([_LOOSE_TILT_RAD, _LOOSE_TILT_RAD, math.radians(sigma_deg)])
        noise = gtsam.noiseModel.Diagonal.Sigmas(sigmas)
        self.graph.add(gtsam.PoseRotationPrior3D(X(0), gtsam.Rot3.Quaternion(w, x, y, z), noise))
        self.report["heading_prior"] = True

    def global_constraint(self, gnss_used: int) -> str:
        """Which measurements tie the clip to the global frame (recorded in the report); NoGlobalConstraint
        when none does."""
        logged = self.config.uses_logged_pose
        if gnss_used:
            constraint = "gnss+logged_pose" if logged else "gnss"
        elif logged:
            constraint = "logged_pose"
        else:
            why = "no GNSS fixes" if self.inputs.gnss is None else "no GNSS fix within the clip's span"
            raise NoGlobalConstraint(
                f"scene {self.inputs.scene!r}: {why} and the logged ego pose is left out (--no-logged-pose, "
                "or every logged_pose_sigmas <= 0): nothing ties the clip to the global frame; fuse the "
                "logged pose (drop --no-logged-pose) for a data set without GNSS"
            )
        self.report["global_constraint"] = constraint
        return constraint

    def logged_pose_factors(self) -> None:
        """The logged ego pose as priors at the nodes within the camera span (the first node when none is),
        their sigmas spread over its errors' correlation time; none when the config leaves it out."""
        if not self.config.uses_logged_pose:
            return
        cam = self.inputs.cameras
        first = np.array([int(np.argmin(np.abs(self.nodes - cam.times_us[0])))])
        inside = np.flatnonzero((self.nodes >= cam.times_us[0]) & (self.nodes <= cam.times_us[-1]))
        chosen = inside if len(inside) else first
        base, flat = logged_pose_sigmas(cam, self.config)  # flat: z = 0 is no height, only the gauge below
        self.report["logged_pose_height"] = FREE_HEIGHT if flat else "fused"
        # n factors within one correlation time carry the information of one measurement
        per_window = self.config.logged_pose_correlation_s * self.config.node_rate_hz
        spread = math.sqrt(min(len(chosen), max(per_window, 1.0)))
        noise = gtsam.noiseModel.Diagonal.Sigmas(base * spread)
        for k in chosen:
            prior = logged_pose_at(cam, int(self.nodes[k]))
            self.graph.add(gtsam.PriorFactorPose3(X(int(k)), prior, noise))
        self.report["logged_pose_factors"] = len(chosen)
        if flat:  # the height's gauge: the first node at the logged z, so that the marginals exist
            gauge = np.array([FREE_SIGMA] * 5 + [FLAT_HEIGHT_GAUGE_SIGMA_M])
            first_node = int(chosen[0])
            prior = logged_pose_at(cam, int(self.nodes[first_node]))
            self.graph.add(
                gtsam.PriorFactorPose3(X(first_node), prior, gtsam.noiseModel.Diagonal.Sigmas(gauge))
            )


def _solve(builder: _GraphBuilder) -> gtsam.Values:
    params = gtsam.LevenbergMarquardtParams()
    params.setMaxIterations(int(builder.config.max_iterations))
    optimizer = gtsam.LevenbergMarquardtOptimizer(builder.graph, builder.initial, params)
    result = optimizer.optimize()
    builder.report["iterations"] = int(optimizer.iterations())
    builder.report["error_initial"] = float(builder.graph.error(builder.initial))
    builder.report["error_final"] = float(builder.graph.error(result))
    return result


def _node_covariances(builder: _GraphBuilder, result: gtsam.Values) -> np.ndarray:
    """(K, 6, 6) marginal covariances of the nodes; NaN with a warning when gtsam cannot give them."""
    n = len(builder.nodes)
    try:
        marginals = gtsam.Marginals(builder.graph, result)
        return np.stack([marginals.marginalCovariance(X(k)) for k in range(n)])
    except RuntimeError as err:
        logger.warning("scene %s: no covariances (%s)", builder.inputs.scene, err)
        return np.full((n, 6, 6), np.nan)


def _gnss_report(
    result: gtsam.Values, used: list[tuple[int, np.ndarray, np.ndarray]], k_width: float
) -> dict:
    """How many fixes ended beyond the robust kernel's width (down-weighted) and their residuals."""
    residuals = [
        float(np.linalg.norm((result.atPose3(X(k)).translation() - pos) / sigma)) for k, pos, sigma in used
    ]
    return {
        "gnss_downweighted": int(sum(r > k_width for r in residuals)),
        "gnss_max_residual_sigmas": max(residuals, default=0.0),
    }


def camera_poses(
    result: gtsam.Values, nodes: np.ndarray, odometry: DeadReckoning, times_us: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(R, t, index, alpha) at `times_us`: odometry from both neighbour nodes, blended on SE(3)."""
    index = np.clip(np.searchsorted(nodes, times_us, side="right") - 1, 0, max(len(nodes) - 2, 0))
    R = np.empty((len(times_us), 3, 3))
    t = np.empty((len(times_us), 3))
    alpha = np.zeros(len(times_us))
    for i, time in enumerate(times_us):
        k = int(index[i])
        at_time = _odometry_pose(odometry, int(time))
        pose = result.atPose3(X(k)).compose(_odometry_pose(odometry, int(nodes[k])).between(at_time))
        if len(nodes) > 1:
            after = _odometry_pose(odometry, int(nodes[k + 1])).between(at_time)
            other = result.atPose3(X(k + 1)).compose(after)
            alpha[i] = float(np.clip((time - nodes[k]) / (nodes[k + 1] - nodes[k]), 0.0, 1.0))
            pose = pose.slerp(alpha[i], other)
        R[i], t[i] = pose.rotation().matrix(), pose.translation()
    return R, t, index, alpha


def fuse_clip(inputs: ClipInputs, config: WigoConfig) -> FusedPoses:
    """Fuse one clip's (checked) inputs into poses at its camera timestamps; NoGlobalConstraint (a ValueError)
    for a clip without GNSS when the config leaves the logged pose out.

    Camera covariances are the neighbour nodes' marginals blended linearly (an approximation: the
    odometry between nodes adds little over 0.1 s)."""
    start, stop = graph_span(inputs, config)
    nodes = node_times(inputs, config, start, stop)
    cam_times = inputs.cameras.times_us
    grid = integration_grid(start, stop, np.concatenate([nodes, cam_times]), config.integration_rate_hz)
    odometry = dead_reckon(inputs, grid, config)
    builder = _GraphBuilder(inputs, config, nodes, odometry)
    builder.initial_values()
    builder.odometry_factors()
    builder.gravity_factors()
    used = builder.gnss_factors()
    constraint = builder.global_constraint(len(used))
    builder.heading_prior()
    builder.logged_pose_factors()
    result = _solve(builder)
    builder.report.update(_gnss_report(result, used, config.gnss_robust_k))
    node_cov = _node_covariances(builder, result)
    R, t, index, alpha = camera_poses(result, nodes, odometry, cam_times)
    upper = np.minimum(index + 1, len(nodes) - 1)
    covariance = (1 - alpha)[:, None, None] * node_cov[index] + alpha[:, None, None] * node_cov[upper]
    logger.info(
        "scene %s: global constraint %s, %d nodes, %d GNSS factors (%d down-weighted), %d LM iterations",
        inputs.scene,
        constraint,
        len(nodes),
        builder.report.get("gnss_factors", 0),
        builder.report["gnss_downweighted"],
        builder.report["iterations"],
    )
    return FusedPoses(
        inputs.scene,
        inputs.cameras.tokens,
        inputs.cameras.channels,
        cam_times,
        R,
        t,
        covariance,
        nodes,
        builder.report,
    )
