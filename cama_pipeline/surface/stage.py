"""The surface stage: for every site of the workspace, the RoMe-style road mesh and its BEV rasters.

Phases per site: surface points (trajectory strip + SfM road points), elevation MLP fit (`fit`), the road
elevation's multi-view refinement against the images (`refine`), observation
(visibility, mean colour and class, ray counts, kerb steps), the joint optimisation by differentiable rendering
(`joint`, off by default) and the vote again on its surface when asked, mesh optimisation, export (see `outputs` for
the files).
"""

import logging
import math
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import asdict
from pathlib import Path
from typing import Any

import torch

from cama_pipeline.bev import write_bev
from cama_pipeline.cameras import CameraView
from cama_pipeline.code_version import code_version
from cama_pipeline.data import Dataset, DatasetError, MaskChoice, load_dataset, mask_roots, masks_fingerprint
from cama_pipeline.fingerprints import file_stats, fingerprint, is_up_to_date
from cama_pipeline.progress import StageProgress
from cama_pipeline.results import ItemResult, StageResult
from cama_pipeline.site.io import read_site_ids, read_site_manifest, read_site_scenes
from cama_pipeline.surface.config import POSE_SOURCES, SurfaceConfig
from cama_pipeline.surface.coverage import extrapolated_heights, weak_observation
from cama_pipeline.surface.fit import fit_steps, fit_surface
from cama_pipeline.surface.joint import render_optimise, road_and_step, vote_config
from cama_pipeline.surface.optimise import new_mesh, observe, optimise
from cama_pipeline.surface.outputs import (
    grid_mesh,
    kerb_step_raster,
    rasters_from_vertices,
    read_report,
    write_kerb_step,
    write_mesh,
    write_report,
)
from cama_pipeline.surface.points import NoRoadPointsError, sfm_surface_points, surface_points
from cama_pipeline.surface.poses import pose_inputs, posed_views
from cama_pipeline.surface.refine import refine_elevation, refine_steps
from cama_pipeline.surface.steps import step_summary
from cama_pipeline.workspace import Workspace

logger = logging.getLogger(__name__)


def pick_device(config: SurfaceConfig) -> torch.device:
    """The GPU when asked or (auto) available, else the CPU."""
    if config.device == "cuda" or (config.device == "auto" and torch.cuda.is_available()):
        return torch.device("cuda")
    return torch.device("cpu")


@contextmanager
def torch_threads(count: int) -> Iterator[None]:
    """torch's intra-op thread count set for the block, restored after."""
    previous = torch.get_num_threads()
    torch.set_num_threads(count)
    try:
        yield
    finally:
        torch.set_num_threads(previous)


class _Phases:
    """One progress bar per phase, its description showing the loss of the phases that have one (NaN: none)."""

    def __init__(self, progress: StageProgress, site_id: str):
        self.progress = progress
        self.site_id = site_id
        self.seconds: dict[str, float] = {}

    @contextmanager
    def phase(self, name: str, total: int) -> Iterator[Callable[[int, float], None]]:
        task = self.progress.add_task(f"{self.site_id} {name}", total=total)
        started = time.perf_counter()

        def advance(done: int, loss: float) -> None:
            shown = "" if math.isnan(loss) else f" loss {loss:.4f}"
            self.progress.update(task, advance=done, description=f"{self.site_id} {name}{shown}")

        yield advance
        self.seconds[name] = round(time.perf_counter() - started, 3)
        self.progress.update(task, completed=total)


def _site_digest(
    config: SurfaceConfig,
    dataset_root: Path,
    workspace: Workspace,
    site_id: str,
    poses: str,
    masks: list[tuple[str, str | None]],
) -> str:
    """Fingerprint of the config, the pose source, the masks (`masks_fingerprint`) and the files the site's
    surface is made from."""
    inputs = [workspace.site_manifest(site_id), *pose_inputs(dataset_root, workspace, site_id, poses)]
    if config.use_sfm_points:
        inputs.append(workspace.sfm_points(site_id))
    return fingerprint(
        code_version("cama_pipeline.surface"), asdict(config), poses, file_stats(inputs), masks
    )


def check_masks(dataset: Dataset, views: list[CameraView], site_id: str) -> None:
    """Every view has a semantic mask (the observation reads them all), else a DatasetError naming the first
    image without one, before any work."""
    missing = [view for view in views if dataset.image(view.token).semantic_mask_path is None]
    if missing:
        searched = ", ".join(str(root) for root in dataset.mask_roots) or "none (the data set has no masks)"
        raise DatasetError(
            f"site {site_id}: {len(missing)} of {len(views)} keyframe images have no semantic mask (mask folders "
            f"searched: {searched}); make them with `cama segment` or `cama import-masks`, or name others with "
            "--masks",
            path=dataset.image(missing[0].token).path,
        )


def reconstruct_site(
    dataset: Dataset, workspace: Workspace, site_id: str, config: SurfaceConfig, poses: str, phases: _Phases
) -> dict[str, Any]:
    """Run every phase on one site and write its outputs; returns the report (without fingerprint)."""
    device = pick_device(config)
    views = posed_views(
        dataset, read_site_manifest(workspace.site_manifest(site_id)), workspace, site_id, poses
    )
    check_masks(dataset, views, site_id)
    sfm_xyz = sfm_surface_points(workspace, site_id, config)
    if poses != "sfm" and len(sfm_xyz):
        logger.warning(
            "site %s: %d SfM road points join the surface on %s poses where SfM placed them, in the SfM frame, "
            "which is not those poses' (README: 'Other pose sources take the SfM points as SfM placed them'); "
            "[surface] use_sfm_points = false leaves them out",
            site_id,
            len(sfm_xyz),
            poses,
        )
    try:
        points = surface_points(views, sfm_xyz, config)
    except NoRoadPointsError as err:
        raise NoRoadPointsError(f"site {site_id} ({poses} poses): {err}") from None
    with phases.phase("elevation", fit_steps(points, config)) as advance:
        fitted = fit_surface(points, config, device, advance)
    grid, mlp, point_tensor = fitted.grid, fitted.mlp, fitted.points
    mesh = new_mesh(grid, mlp, config, device)
    with phases.phase("refine", refine_steps(len(views), config)) as advance:
        refined = refine_elevation(mesh, dataset, views, config, advance)
    with phases.phase("observe", len(views)) as advance:
        visible = observe(mesh, dataset, views, config, advance)
    with phases.phase("joint", len(views) * config.joint.epochs) as advance:
        joint_losses = render_optimise(mesh, dataset, views, config, advance)
    if config.joint.epochs and config.joint.vote_after:
        with phases.phase("vote_after_joint", len(views)) as advance:
            observe(mesh, dataset, views, vote_config(config), advance)
    with phases.phase("optimise", len(views) * config.epochs) as advance:
        epoch_losses = optimise(mesh, dataset, views, visible, point_tensor, config, advance)
    with phases.phase("export", 1) as advance, torch.no_grad():
        base = mesh.control.at_vertices(mesh.control_heights()).cpu().numpy()
        labels = mesh.logits.argmax(dim=1).cpu().numpy().astype("uint8")
        count = mesh.count.cpu().numpy()
        heights, step = road_and_step(
            base, mesh.step.cpu().numpy(), mesh.residual.cpu().numpy(), labels, config.curb_height_m
        )
        rasters = rasters_from_vertices(grid, heights, mesh.colour.cpu().numpy(), labels, count)
        kerb_step = kerb_step_raster(grid, step, count)
        write_bev(workspace.surface_bev(site_id), rasters)
        write_kerb_step(workspace.surface_kerb_step(site_id), kerb_step)
        write_mesh(workspace.surface_mesh(site_id), grid_mesh(grid, rasters, kerb_step))
        advance(1, math.nan)
    return {
        "site_id": site_id,
        "poses": poses,
        "config": asdict(config),
        "device": str(device),
        "images": len(views),
        "points": {
            "strip": points.strip_count,
            "sfm": points.sfm_count,
            "sfm_kept": fitted.sfm_kept,
            "sfm_frame_is_the_poses": poses == "sfm" or not points.sfm_count,
        },
        "vertices": grid.vertex_count,
        "cells_observed": int((rasters.require("observation_count") > 0).sum()),
        "kerb_step": step_summary(rasters.require("semantic"), kerb_step, config.curb_height_m),
        "weak_observation": weak_observation(
            rasters.require("observation_count"),
            rasters.require("semantic"),
            rasters.georeference,
            config.coverage,
        ),
        "extrapolated_heights": extrapolated_heights(
            point_tensor[:, :2].cpu().numpy(),
            rasters.require("observation_count"),
            rasters.require("semantic"),
            rasters.georeference,
            config.coverage,
        ),
        "seconds": dict(phases.seconds),
        "losses": {
            "elevation": fitted.losses,
            "refine": refined,
            "joint": joint_losses,
            "epochs": epoch_losses,
        },
    }


def run(
    config: SurfaceConfig,
    dataset_root: Path,
    workspace: Path | Workspace | None = None,
    *,
    poses: str = "wigo",
    masks: MaskChoice | str = "auto",
    overwrite: bool = False,
    show_progress: bool = True,
) -> StageResult:
    """Surface mesh and BEV rasters of every site in `sites/index.json` (after `cama sites`), posed by
    `poses` (ground_truth: synthetic sites only; wigo: the site manifest; sfm: after `cama sfm`), observed
    through the semantic masks of `masks` (`cama_pipeline.data.masks`)."""
    if poses not in POSE_SOURCES:
        raise ValueError(f"poses must be one of {', '.join(POSE_SOURCES)}, got {poses!r}")
    started = time.perf_counter()
    ws = Workspace.resolve(workspace, Path(dataset_root))
    site_ids = read_site_ids(ws.sites_index())
    roots = mask_roots(masks, Path(dataset_root), ws)
    masks_part = masks_fingerprint(masks, roots, Path(dataset_root))
    dataset: Dataset | None = None
    done: list[ItemResult] = []
    with (
        StageProgress("surface", logger=logger, enabled=show_progress) as progress,
        torch_threads(config.torch_threads),
    ):
        for site_id in site_ids:
            digest = _site_digest(config, Path(dataset_root), ws, site_id, poses, masks_part)
            path, folder = ws.surface_report(site_id), ws.surface_dir(site_id)
            if not overwrite and is_up_to_date(path, digest):
                done.append(ItemResult(site_id, folder, read_report(path), skipped=True))
                continue
            dataset = dataset or load_dataset(
                Path(dataset_root), mask_roots=roots, scenes=read_site_scenes(ws.sites_index())
            )
            torch.manual_seed(config.seed)
            report = reconstruct_site(dataset, ws, site_id, config, poses, _Phases(progress, site_id))
            report = write_report(path, {**report, "fingerprint": digest})
            logger.info(
                "site %s: %d cells observed, %s s", site_id, report["cells_observed"], report["seconds"]
            )
            done.append(ItemResult(site_id, folder, report, skipped=False))
    return StageResult("surface", ws, tuple(done), time.perf_counter() - started)
