"""Bundle adjustment of a guided model: plain (every image's pose free) or rigid (one pose per keyframe,
camera-to-rig transforms constant or refined), intrinsics constant, robust loss, optional odometry priors.

Gauge: with odometry priors the priors hold the model in place; without them the first keyframe's
cameras are held (their spread fixes the scale; with refined extrinsics a second keyframe is held too).
"""

import logging
import math
import time
from typing import Any

import numpy as np
import pycolmap

from cama_pipeline.sfm.config import SfmConfig
from cama_pipeline.sfm.model import GuidedModel, frame_pose, matrix_from_rigid
from cama_pipeline.sfm.priors import add_odometry_priors

logger = logging.getLogger(__name__)
_LOSSES = {
    "cauchy": pycolmap.LossFunctionType.CAUCHY,
    "huber": pycolmap.LossFunctionType.HUBER,
    "trivial": pycolmap.LossFunctionType.TRIVIAL,
}


def ba_options(config: SfmConfig) -> pycolmap.BundleAdjustmentOptions:
    """Poses and points refined; intrinsics constant; extrinsics refined only when asked."""
    options = pycolmap.BundleAdjustmentOptions()
    options.refine_focal_length = False
    options.refine_principal_point = False
    options.refine_extra_params = False
    options.refine_sensor_from_rig = config.rigid and config.refine_extrinsics
    options.print_summary = False
    options.ceres.loss_function_type = _LOSSES[config.loss]
    options.ceres.loss_function_scale = config.loss_scale_px
    options.ceres.solver_options.max_num_iterations = config.ba_max_iterations
    options.ceres.solver_options.function_tolerance = config.ba_function_tolerance
    options.ceres.solver_options.num_threads = config.num_threads
    return options


def ba_config(model: GuidedModel, config: SfmConfig) -> pycolmap.BundleAdjustmentConfig:
    """Every registered image, constant intrinsics, and the gauge (see the module docstring)."""
    setup = pycolmap.BundleAdjustmentConfig()
    reconstruction = model.reconstruction
    for image_id in reconstruction.reg_image_ids():
        setup.add_image(image_id)
    for camera_id in reconstruction.cameras:
        setup.set_constant_cam_intrinsics(camera_id)
    if not (config.rigid and config.refine_extrinsics):
        for rig in reconstruction.rigs.values():
            for sensor_id in rig.non_ref_sensors:
                setup.set_constant_sensor_from_rig_pose(sensor_id)
    if config.odometry_priors:
        return setup
    held = first_keyframe(model)
    if config.refine_extrinsics:  # free extrinsics leave the scale free: hold a second keyframe too
        later = [i for i in model.registered_frame_ids() if i not in held]
        held += first_keyframe(model, later[:1]) if later else []
    for frame_id in held:
        setup.set_constant_rig_from_world_pose(frame_id)
    return setup


def first_keyframe(model: GuidedModel, among: list[int] | None = None) -> list[int]:
    """The registered frames of the first keyframe (one rig frame, or its images' frames in plain BA)."""
    frame_ids = model.registered_frame_ids() if among is None else among
    if not frame_ids:
        return []
    first = model.frames[frame_ids[0]]
    return [
        i
        for i in frame_ids
        if (model.frames[i].scene, model.frames[i].frame_index) == (first.scene, first.frame_index)
    ]


def bundle_adjust(model: GuidedModel, config: SfmConfig) -> dict[str, Any]:
    """One BA of the model in place; what it did (costs, iterations, priors, seconds, largest pose move)."""
    started = time.perf_counter()
    before = {i: matrix_from_rigid(frame_pose(model.reconstruction, i)) for i in model.registered_frame_ids()}
    adjuster = pycolmap.create_default_ceres_bundle_adjuster(
        ba_options(config), ba_config(model, config), model.reconstruction
    )
    priors, costs = (
        add_odometry_priors(adjuster.problem, model, config) if config.odometry_priors else ({}, [])
    )
    summary = adjuster.solve()
    del costs  # alive until here: the problem refers to them
    moved = [
        _pose_change(pose, matrix_from_rigid(frame_pose(model.reconstruction, i)))
        for i, pose in before.items()
    ]
    return {
        **_solver_report(summary),
        "priors": priors,
        "max_move_m": max((m for m, _ in moved), default=0.0),
        "max_turn_deg": max((d for _, d in moved), default=0.0),
        "seconds": time.perf_counter() - started,
    }


def _solver_report(summary: pycolmap.BundleAdjustmentSummary) -> dict[str, Any]:
    """Costs and iterations of the Ceres solve (the summary is Ceres's when the backend is)."""
    ceres = getattr(summary, "ceres_summary", None)
    if ceres is None:
        return {"usable": bool(summary.is_solution_usable())}
    return {
        "usable": bool(summary.is_solution_usable()),
        "initial_cost": float(ceres.initial_cost),
        "final_cost": float(ceres.final_cost),
        "solver_iterations": int(ceres.num_successful_steps + ceres.num_unsuccessful_steps),
    }


def _pose_change(a_from_world: np.ndarray, b_from_world: np.ndarray) -> tuple[float, float]:
    """Distance (m) between two camera centres and the angle (deg) between their orientations."""
    shift = np.linalg.norm(np.linalg.inv(a_from_world)[:3, 3] - np.linalg.inv(b_from_world)[:3, 3])
    relative = a_from_world[:3, :3] @ b_from_world[:3, :3].T
    angle = math.degrees(math.acos(float(np.clip((np.trace(relative) - 1) / 2, -1.0, 1.0))))
    return float(shift), angle


def implausible_frames(model: GuidedModel, config: SfmConfig) -> dict[int, str]:
    """Registered frames that BA moved further from their odometry pose than the config allows, with why."""
    flagged = {}
    for frame_id in model.registered_frame_ids():
        now = matrix_from_rigid(frame_pose(model.reconstruction, frame_id))
        shift, angle = _pose_change(model.frames[frame_id].initial_rig_from_world, now)
        if shift > config.max_camera_shift_m or angle > config.max_camera_rotation_deg:
            flagged[frame_id] = f"moved {shift:.2f} m / {angle:.2f} deg from its odometry pose"
    return flagged
