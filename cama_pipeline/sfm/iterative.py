"""Refinement after the first triangulation: one BA pass, or the paper's iterative BA (Algorithm 1).

Algorithm 1, per iteration i: retriangulate; O_i = observations; BA; post-BA retriangulation; filter points
by reprojection error and track length; C_i = observations changed by that retriangulation and filtering;
stop when C_i / O_i <= max refinement change; else drop images with a high reprojection error and repeat,
up to the maximum number of iterations. Frames that BA moved implausibly far are dropped after every BA
(the paper's rigid prior).
"""

import logging
from collections.abc import Callable
from dataclasses import replace
from typing import Any

from cama_pipeline.sfm.bundle import bundle_adjust, implausible_frames
from cama_pipeline.sfm.config import SfmConfig
from cama_pipeline.sfm.model import GuidedModel
from cama_pipeline.sfm.triangulate import filter_points, image_reprojection_errors, retriangulate

logger = logging.getLogger(__name__)
Progress = Callable[[str, int, int], None]


def _adjust(model: GuidedModel, config: SfmConfig) -> dict[str, Any]:
    """BA, then drop the frames it moved implausibly far."""
    report = bundle_adjust(model, config)
    moved = implausible_frames(model, config)
    for frame_id, reason in moved.items():
        model.drop_frame(frame_id, reason)
    report["dropped_frames"] = len(moved)
    return report


def high_error_frames(model: GuidedModel, config: SfmConfig) -> dict[int, str]:
    """Registered frames whose mean reprojection error (over all their images' observations) is too high."""
    totals: dict[int, list[float]] = {}
    for image_id, (error, count) in image_reprojection_errors(model.reconstruction).items():
        frame_id = model.reconstruction.image(image_id).frame_id
        total = totals.setdefault(frame_id, [0.0, 0.0])
        total[0] += error * count
        total[1] += count
    return {
        frame_id: f"mean reprojection error {weighted / count:.2f} px"
        for frame_id, (weighted, count) in totals.items()
        if weighted / count > config.max_image_reprojection_error_px
    }


def single_pass(model: GuidedModel, config: SfmConfig, progress: Progress) -> dict[str, Any]:
    """One BA after triangulation, then point filtering (variants b and c of the benchmark)."""
    progress("bundle adjustment", 0, 1)
    report = _adjust(model, config)
    report["filtered_observations"] = filter_points(model, config)
    progress("bundle adjustment", 1, 1)
    return {"iterations": [report], "stop": "single_pass"}


def _pass_config(config: SfmConfig, iteration: int) -> SfmConfig:
    """The config of one iteration's BA: the first may be capped (`first_ba_max_iterations`)."""
    if iteration > 1 or config.first_ba_max_iterations is None:
        return config
    return replace(config, ba_max_iterations=config.first_ba_max_iterations)


def iterative_bundle_adjustment(model: GuidedModel, config: SfmConfig, progress: Progress) -> dict[str, Any]:
    """Algorithm 1 (see the module docstring); one report entry per iteration and why it stopped."""
    iterations: list[dict[str, Any]] = []
    stop = "max_iterations"
    for i in range(1, config.max_iterations + 1):
        progress("iterative BA", i - 1, config.max_iterations)
        retriangulated = retriangulate(model, config)
        observations = int(model.reconstruction.compute_num_observations())
        report = _adjust(model, _pass_config(config, i))
        post_ba = retriangulate(model, config)
        filtered = filter_points(model, config)
        ratio = (post_ba + filtered) / max(observations, 1)
        report.update(
            iteration=i,
            retriangulated=retriangulated,
            observations=observations,
            post_ba_retriangulated=post_ba,
            filtered_observations=filtered,
            changed_ratio=ratio,
        )
        iterations.append(report)
        logger.info("iteration %d: %d observations, changed ratio %.5f", i, observations, ratio)
        if ratio <= config.max_refinement_change:
            stop = "converged"
            break
        bad = high_error_frames(model, config)
        for frame_id, reason in bad.items():
            model.drop_frame(frame_id, reason)
        report["dropped_high_error_frames"] = len(bad)
    progress("iterative BA", config.max_iterations, config.max_iterations)
    return {"iterations": iterations, "stop": stop}
