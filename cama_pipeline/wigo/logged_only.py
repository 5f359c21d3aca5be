"""A clip without wheel speeds: its logged ego poses as they are, with the logged pose's sigmas as covariance.

nuScenes' CAN bus expansion does not cover every scene, and the devkit lists some of the ones it covers as
faulty. Without wheel speeds the pose graph has no odometry scale, so there is nothing to fuse; refusing such a
scene would stop a whole `cama run` over a location. The stage passes its logged poses through instead
(`WigoConfig.without_wheels = "logged_pose"`, the default) and says so in the report's `odometry`; SfM then
refines them as it refines fused ones, the logged poses' sigmas standing for their uncertainty.
"""

import numpy as np

from cama_pipeline.wigo.config import WigoConfig
from cama_pipeline.wigo.fusion import (
    FLAT_HEIGHT_GAUGE_SIGMA_M,
    FREE_HEIGHT,
    FusedPoses,
    NoGlobalConstraint,
    logged_pose_sigmas,
)
from cama_pipeline.wigo.inputs import LoggedPoses

NO_ODOMETRY = "none: no wheel speeds; the logged ego poses as they are"
"""The report's `odometry` of a clip passed through."""


def logged_pose_clip(scene: str, cameras: LoggedPoses, config: WigoConfig) -> FusedPoses:
    """The logged poses of a clip without wheel speeds as its WIGO poses. Each pose's covariance is diagonal,
    in gtsam's body tangent order [rx, ry, rz, tx, ty, tz], from `config.logged_pose_sigmas` (a component left
    free, and the height of a 2D localization whose z are all 0, get a loose sigma). NoGlobalConstraint when
    the config leaves the logged pose out: then nothing at all places the clip."""
    if not config.uses_logged_pose:
        raise NoGlobalConstraint(
            f"scene {scene!r}: no wheel speeds and the logged ego pose is left out (--no-logged-pose): nothing "
            "gives the clip's poses"
        )
    sigmas, flat = logged_pose_sigmas(cameras, config)
    if flat:  # the height as loose as the fusion's gauge leaves it
        sigmas[5] = FLAT_HEIGHT_GAUGE_SIGMA_M
    covariance = np.diag(sigmas**2)
    report = {
        "odometry": NO_ODOMETRY,
        "global_constraint": "logged_pose",
        "logged_pose_height": FREE_HEIGHT if flat else "fused",
        "degraded": ["no wheel speeds: the logged ego poses are passed through, not fused"],
    }
    return FusedPoses(
        scene,
        cameras.tokens,
        cameras.channels,
        cameras.times_us,
        cameras.rotation.copy(),
        cameras.translation.copy(),
        np.repeat(covariance[None], len(cameras.tokens), axis=0),
        np.unique(cameras.times_us),
        report,
    )
