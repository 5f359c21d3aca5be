"""Odometry-guided SfM of a set of views (a clip, or the union of merged clips): the known-pose model from
WIGO poses and calibration (real-world scale), triangulation of every verified match from those poses,
then one BA or the iterative BA, plain or rigid, with optional odometry priors (paper: OGI, rigid prior,
Algorithm 1). The pure API the `cama sfm` stage builds on; it writes nothing outside a temporary folder.
"""

import logging
import tempfile
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import pycolmap

from cama_pipeline.cameras import CameraView
from cama_pipeline.sfm.config import SfmConfig
from cama_pipeline.sfm.errors import SfmError
from cama_pipeline.sfm.gauge import apply_gauge, fit_gauge
from cama_pipeline.sfm.iterative import iterative_bundle_adjustment, single_pass
from cama_pipeline.sfm.model import GuidedModel, build_model, clip_label, matrix_from_rigid
from cama_pipeline.sfm.triangulate import SeedPoints, seed_points, triangulate_all

logger = logging.getLogger(__name__)
Progress = Callable[[str, int, int], None]


@dataclass(frozen=True, eq=False)
class GuidedResult:
    """A guided reconstruction: the sparse model, what happened, and the images dropped on the way."""

    reconstruction: pycolmap.Reconstruction
    """Registered images keep the features database's image ids and names; cameras are one per channel
    and calibration; rigs and frames as in `cama_pipeline.sfm.model`. Not picklable: write it to move it."""
    report: dict[str, Any]
    """JSON-able: images, registered_images, points, mean_reprojection_error_px, iterations (one dict per
    BA pass or Algorithm 1 iteration), stop, flagged_images {name: reason}, seconds per phase."""
    flagged: tuple[str, ...]
    """Image names dropped (moved implausibly far in BA, or high reprojection error)."""
    world_from_ego: dict[str, np.ndarray] = field(default_factory=dict)
    """(4, 4) refined ego pose by image name, for every registered, unflagged image."""


def _no_progress(phase: str, done: int, total: int) -> None:
    """Progress sink when the caller wants none."""


def _check_inputs(views: Sequence[CameraView], database_path: Path, image_dir: Path) -> None:
    if not views:
        raise ValueError("reconstruct_views: no views given")
    if not Path(database_path).is_file():
        raise FileNotFoundError(f"{database_path}: features database not found; run `cama features` first")
    if not Path(image_dir).is_dir():
        raise FileNotFoundError(f"{image_dir}: image folder not found")


def _check_model(model: GuidedModel, views: Sequence[CameraView], config: SfmConfig, phase: str) -> None:
    """SfmError naming the clip when too few points or keyframes are left."""
    reconstruction = model.reconstruction
    points, frames = reconstruction.num_points3D(), len(model.registered_frame_ids())
    if points < config.min_points or frames < config.min_registered_frames:
        names = sorted(view.name for view in views)
        raise SfmError(
            f"clip {clip_label(views)}: {points} points and {frames} registered keyframes after {phase} "
            f"(need {config.min_points} and {config.min_registered_frames}); "
            f"images {', '.join(names[:3])}{' ...' if len(names) > 3 else ''}"
        )


def _summary(model: GuidedModel, views: Sequence[CameraView], refinement: dict[str, Any]) -> dict[str, Any]:
    reconstruction = model.reconstruction
    return {
        "images": len(views),
        "registered_images": int(reconstruction.num_reg_images()),
        "points": int(reconstruction.num_points3D()),
        "observations": int(reconstruction.compute_num_observations()),
        "mean_track_length": float(reconstruction.compute_mean_track_length()),
        "mean_reprojection_error_px": float(reconstruction.compute_mean_reprojection_error()),
        **refinement,
        "flagged_images": dict(sorted(model.flagged.items())),
    }


def reconstruct_views(
    views: Sequence[CameraView],
    database_path: Path,
    image_dir: Path,
    config: SfmConfig,
    *,
    progress: Progress | None = None,
    odometry: Mapping[str, np.ndarray] | None = None,
    seeds: Sequence[SeedPoints] = (),
) -> GuidedResult:
    """Guided SfM of these images (names as in the COLMAP database at `database_path`, poses and
    calibration from the views) from the verified matches in the database; point colours from `image_dir`.

    Any subset of a site's views works, with any initial poses. With `config.anchor_gauge` the result is
    moved onto the `odometry` world_from_ego poses by image name (default: the views' own). With `seeds`
    (the merge: points its clips triangulated and refined) those points start the model instead of a
    triangulation of every match from scratch. Raises SfmError
    naming the clip when it cannot be reconstructed (no matches, too few points or keyframes).
    """
    _check_inputs(views, database_path, image_dir)
    report = progress or _no_progress
    seconds: dict[str, float] = {}
    started = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="cama-sfm-") as work_dir:
        report("model", 0, 1)
        model = build_model(views, Path(database_path), Path(work_dir), config)
        seconds["model"] = time.perf_counter() - started
        report("triangulate", 0, 1)
        if seeds:
            seed_points(model, seeds, config)
        else:
            triangulate_all(model, config)
        _check_model(model, views, config, "triangulation")
        seconds["triangulate"] = time.perf_counter() - started - sum(seconds.values())
        refine = iterative_bundle_adjustment if config.iterative else single_pass
        refinement = refine(model, config, report)
        _check_model(model, views, config, "bundle adjustment")
        seconds["refine"] = time.perf_counter() - started - sum(seconds.values())
        model.mapper.end_reconstruction(False)
    report("colours", 0, 1)
    model.reconstruction.extract_colors_for_all_images(str(image_dir), config.num_threads)
    seconds["colours"] = time.perf_counter() - started - sum(seconds.values())
    poses = _refined_poses(model, views)
    gauge = None
    if config.anchor_gauge:
        reference = odometry if odometry is not None else {view.name: view.world_from_ego for view in views}
        gauge, poses = anchor(model.reconstruction, poses, reference, config)
    summary = {**_summary(model, views, refinement), "gauge": gauge, "seconds": seconds}
    logger.info(
        "clip %s: %d/%d images, %d points, %.2f px",
        clip_label(views),
        summary["registered_images"],
        summary["images"],
        summary["points"],
        summary["mean_reprojection_error_px"],
    )
    return GuidedResult(model.reconstruction, summary, tuple(sorted(model.flagged)), poses)


def anchor(
    reconstruction: pycolmap.Reconstruction,
    world_from_ego: dict[str, np.ndarray],
    odometry: Mapping[str, np.ndarray],
    config: SfmConfig,
) -> tuple[dict[str, Any] | None, dict[str, np.ndarray]]:
    """Move the model and its refined ego poses onto the odometry poses (see `cama_pipeline.sfm.gauge`);
    the fit's report (None when too few poses are shared) and the moved poses. A scaled fit scales the whole
    model, the camera-to-rig translations of its rigs included."""
    fit = fit_gauge(world_from_ego, odometry, config.gauge_sigmas(), fit_scale=config.gauge_fit_scale)
    if fit is None:
        return None, world_from_ego
    apply_gauge(reconstruction, fit.new_from_old)
    logger.info(
        "gauge: moved %.3f m, turned %.4f deg, scaled by %.5f onto %d odometry poses",
        fit.shift_m,
        fit.rotation_deg,
        fit.scale,
        fit.poses,
    )
    return fit.to_json(), {name: fit.move_pose(pose) for name, pose in world_from_ego.items()}


def _refined_poses(model: GuidedModel, views: Sequence[CameraView]) -> dict[str, np.ndarray]:
    """Refined world_from_ego of every image of every registered frame, at the image's own capture time
    (from its camera pose and extrinsics; a keyframe's cameras fire tens of ms apart)."""
    registered = {name for i in model.registered_frame_ids() for name in model.frames[i].image_names}
    poses = {}
    for view in views:
        if view.name in registered:
            image = model.reconstruction.image(model.image_ids[view.name])
            world_from_cam = np.linalg.inv(matrix_from_rigid(image.cam_from_world()))
            poses[view.name] = world_from_cam @ np.linalg.inv(view.ego_from_cam)
    return poses


def refined_views(result: GuidedResult, views: Sequence[CameraView]) -> list[CameraView]:
    """The views with world_from_ego replaced by the refined pose (flagged / unregistered views dropped)."""
    return [
        replace(view, world_from_ego=result.world_from_ego[view.name])
        for view in views
        if view.name in result.world_from_ego
    ]
