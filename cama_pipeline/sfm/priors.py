"""Odometry priors inside BA: relative-pose residuals between consecutive keyframes (WIGO's motion) and an
absolute pose residual per keyframe (GNSS-like position plus a loose orientation anchor, without which roll
about a straight trajectory is free), added to pycolmap's Ceres problem on `frame.rig_from_world.params`."""

import logging
import math

import numpy as np
import pyceres
import pycolmap
import pycolmap.cost_functions

from cama_pipeline.sfm.config import SfmConfig
from cama_pipeline.sfm.model import FrameInfo, GuidedModel, frame_pose, rigid_from_matrix

logger = logging.getLogger(__name__)


def _covariance(rotation_sigma_rad: float, translation_sigma_m: float) -> np.ndarray:
    """(6, 6) diagonal covariance, rotation first (pycolmap's order)."""
    return np.diag([rotation_sigma_rad**2] * 3 + [translation_sigma_m**2] * 3)


def odometry_neighbours(model: GuidedModel, frame_ids: list[int]) -> list[tuple[FrameInfo, FrameInfo]]:
    """Consecutive registered frames of one clip and one reference camera (the odometry chain)."""
    frames = sorted(
        (model.frames[i] for i in frame_ids), key=lambda f: (f.scene, f.channel, f.frame_index, f.frame_id)
    )
    return [
        (first, second)
        for first, second in zip(frames, frames[1:], strict=False)
        if (first.scene, first.channel) == (second.scene, second.channel)
    ]


def add_odometry_priors(
    problem: pyceres.Problem, model: GuidedModel, config: SfmConfig
) -> tuple[dict[str, int], list[pyceres.CostFunction]]:
    """Add the prior residuals of the registered frames to `problem`; counts of each kind, and the cost
    functions, which the caller keeps alive until the problem is solved (the problem does not own them)."""
    frame_ids = model.registered_frame_ids()
    relative = _covariance(
        math.radians(config.relative_rotation_sigma_deg), config.relative_translation_sigma_m
    )
    absolute = _covariance(math.radians(config.anchor_rotation_sigma_deg), config.position_sigma_m)
    counts = {"relative": 0, "absolute": 0}
    costs: list[pyceres.CostFunction] = []
    for first, second in odometry_neighbours(model, frame_ids):
        first_from_second = first.initial_rig_from_world @ np.linalg.inv(second.initial_rig_from_world)
        cost = pycolmap.cost_functions.RelativePosePriorCost(relative, rigid_from_matrix(first_from_second))
        costs.append(cost)
        problem.add_residual_block(
            cost,
            None,
            [
                frame_pose(model.reconstruction, first.frame_id).params,
                frame_pose(model.reconstruction, second.frame_id).params,
            ],
        )
        counts["relative"] += 1
    for frame_id in frame_ids:
        prior = rigid_from_matrix(model.frames[frame_id].initial_rig_from_world)
        cost = pycolmap.cost_functions.AbsolutePosePriorCost(absolute, prior)
        costs.append(cost)
        problem.add_residual_block(cost, None, [frame_pose(model.reconstruction, frame_id).params])
        counts["absolute"] += 1
    return counts, costs
