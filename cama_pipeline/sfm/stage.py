"""The SfM stage: every site of the workspace reconstructed clip by clip in parallel (odometry-guided SfM on
each clip's images, in its own process), the clips merged where they share points, then started from
the clips' refined points, re-triangulated and bundle-adjusted as one model. Outputs and their schema: `cama_pipeline.sfm.io`.

A clip is a moving scene of the site with the stationary scenes merged into it. A clip whose SfM fails
(night, too few matches) is reported and left out; the rest of the site still reconstructs.
"""

import logging
import shutil
import sqlite3
import tempfile
import time
from collections.abc import Callable, Collection
from contextlib import closing
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import pycolmap

from cama_pipeline.cameras import CameraView, site_views
from cama_pipeline.code_version import code_version
from cama_pipeline.data import Dataset, MaskChoice, load_dataset, mask_roots, masks_fingerprint
from cama_pipeline.fingerprints import file_stats, fingerprint, is_up_to_date, stored_fingerprint
from cama_pipeline.progress import StageProgress
from cama_pipeline.results import ItemResult, StageResult
from cama_pipeline.sfm.config import SfmConfig
from cama_pipeline.sfm.errors import SfmError
from cama_pipeline.sfm.executor import Executor, make_executor
from cama_pipeline.sfm.guided import GuidedResult, reconstruct_views, refined_views
from cama_pipeline.sfm.height_ties import HeightTie, alignment_priors, tie_heights
from cama_pipeline.sfm.io import (
    PoseEntry,
    read_model,
    read_report,
    write_model,
    write_points,
    write_poses,
    write_report,
)
from cama_pipeline.sfm.labels import MaskReader, dataset_masks, sparse_points
from cama_pipeline.sfm.merge import (
    ClipModel,
    MergeConfig,
    align_clips,
    aligned_views,
    cross_clip_matches,
    merge_groups,
)
from cama_pipeline.sfm.triangulate import model_seeds
from cama_pipeline.site.io import read_site_ids, read_site_manifest, read_site_scenes
from cama_pipeline.wigo.stage import free_height_scenes
from cama_pipeline.workspace import Workspace

logger = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class ClipTask:
    """One clip's reconstruction, as sent to a worker process (picklable)."""

    scene: str
    views: tuple[CameraView, ...]
    database: Path
    """A consistent copy of the site's features database (see `copy_database`), copied again per task."""
    image_dir: Path
    config: SfmConfig
    model_dir: Path
    """Where the worker writes the clip's model."""


@dataclass(frozen=True, eq=False)
class ClipOutcome:
    """What a worker sends back: the clip's refined views and report, or why it failed."""

    scene: str
    ok: bool
    error: str | None
    views: tuple[CameraView, ...]
    flagged: tuple[str, ...]
    report: dict[str, Any]
    seconds: float


def model_summary(reconstruction: pycolmap.Reconstruction, images: int) -> dict[str, Any]:
    """Registered images, points and mean reprojection error of a model."""
    return {
        "images": images,
        "registered_images": reconstruction.num_reg_images(),
        "points": reconstruction.num_points3D(),
        "reprojection_error_px": float(reconstruction.compute_mean_reprojection_error()),
    }


def _summary(result: GuidedResult, images: int) -> dict[str, Any]:
    """Summary of a guided result: the model's figures, its BA passes and flagged images."""
    iterations = result.report.get("iterations")
    return {
        **model_summary(result.reconstruction, images),
        "iterations": len(iterations) if isinstance(iterations, list) else iterations,
        "stop": result.report.get("stop"),
        "flagged": len(result.flagged),
        "gauge": result.report.get("gauge"),
    }


def copy_database(source: Path, target: Path) -> Path:
    """A consistent standalone copy of a SQLite database (its write-ahead log included)."""
    target.parent.mkdir(parents=True, exist_ok=True)
    with (
        closing(sqlite3.connect(f"file:{source}?mode=ro", uri=True)) as src,
        closing(sqlite3.connect(target)) as dst,
    ):
        src.backup(dst)
    return target


def reconstruct_clip(task: ClipTask) -> ClipOutcome:
    """Guided SfM of one clip (runs in a worker, on its own copy of the database: pycolmap locks the file
    it opens); SfM failures become a failed outcome, not an exception."""
    pycolmap.logging.minloglevel = 2
    started = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix=f"cama-sfm-{task.scene}-") as scratch:
        database = Path(shutil.copyfile(task.database, Path(scratch) / "database.db"))
        try:
            result = reconstruct_views(task.views, database, task.image_dir, task.config)
        except SfmError as err:
            return ClipOutcome(task.scene, False, str(err), (), (), {}, time.perf_counter() - started)
    write_model(task.model_dir, result.reconstruction)
    return ClipOutcome(
        task.scene,
        True,
        None,
        tuple(refined_views(result, task.views)),
        result.flagged,
        _summary(result, len(task.views)),
        time.perf_counter() - started,
    )


def site_clips(views: list[CameraView], manifest: dict[str, Any]) -> dict[str, list[CameraView]]:
    """The site's views by clip: each moving scene with the stationary scenes merged into it."""
    clip_of = {s["scene"]: s.get("merged_into") or s["scene"] for s in manifest["scenes"]}
    clips: dict[str, list[CameraView]] = {}
    for view in views:
        clips.setdefault(clip_of.get(view.scene, view.scene), []).append(view)
    return clips


@dataclass(frozen=True, eq=False)
class SiteReconstruction:
    """A site's merged model and how it was made."""

    reconstruction: pycolmap.Reconstruction
    views: tuple[CameraView, ...]
    """Registered views with their refined poses."""
    flagged: tuple[CameraView, ...]
    """Views dropped by a clip's or the merged BA, with the pose they had going in."""
    report: dict[str, Any]
    clips: tuple[ClipOutcome, ...] = field(default=())


def _clip_tasks(
    clips: dict[str, list[CameraView]], database: Path, image_dir: Path, config: SfmConfig, clips_dir: Path
) -> list[ClipTask]:
    return [
        ClipTask(scene, tuple(views), database, Path(image_dir), config, clips_dir / scene)
        for scene, views in clips.items()
    ]


def run_clips(
    tasks: list[ClipTask], executor: Executor, progress: StageProgress | None = None
) -> list[ClipOutcome]:
    """Every clip on the executor, the progress bar advancing as each finishes; failures logged."""
    bar = progress.add_task("clips", total=len(tasks)) if progress is not None else None

    def done(index: int) -> None:
        if progress is not None and bar is not None:
            progress.advance(bar)
        logger.info("clip %s done", tasks[index].scene)

    outcomes = executor.map(reconstruct_clip, tasks, on_done=done)
    for outcome in outcomes:
        if not outcome.ok:
            logger.warning("clip %s failed and is left out: %s", outcome.scene, outcome.error)
    return outcomes


def _phase_reporter(progress: StageProgress | None, label: str) -> Callable[[str, int, int], None] | None:
    """A guided-SfM progress callback that shows the phase and iteration on a bar of `progress`."""
    if progress is None:
        return None
    bar = progress.add_task(label, total=None)

    def report(phase: str, done: int, total: int) -> None:
        progress.update(bar, description=f"{label}: {phase}", completed=done, total=total or None)

    return report


def merge_site(
    outcomes: list[ClipOutcome],
    tasks: list[ClipTask],
    config: SfmConfig,
    merge_config: MergeConfig,
    progress: StageProgress | None = None,
    free_height: Collection[str] = (),
) -> tuple[GuidedResult, list[CameraView], dict[str, Any]]:
    """Align the successful clips (the heights of `free_height` scenes not joined by points tied to the
    others', `height_ties`), then re-triangulate and adjust their union as one model: (its result, the aligned
    views that went in, the merge report). SfmError when every clip failed."""
    task_of = {task.scene: task for task in tasks}
    models = [ClipModel(o.scene, read_model(task_of[o.scene].model_dir), o.views) for o in outcomes if o.ok]
    if not models:
        reasons = "; ".join(f"{o.scene}: {o.error}" for o in outcomes)
        raise SfmError(f"every clip failed ({reasons})")
    database, image_dir = tasks[0].database, tasks[0].image_dir
    priors, first_ties = alignment_priors(models, free_height, merge_config)
    ties: dict[str, HeightTie] = {}
    alignments = align_clips(models, cross_clip_matches(database), merge_config, priors)
    if merge_config.height_ties:
        alignments, ties = tie_heights(
            models,
            alignments,
            free_height,
            radius_m=merge_config.height_tie_radius_m,
            min_pairs=merge_config.height_tie_min_pairs,
        )
    union = [
        v for m, a in zip(models, alignments, strict=True) for v in aligned_views(m.views, a.world_from_clip)
    ]
    merged_config = replace(
        config,
        max_iterations=min(config.max_iterations, merge_config.global_max_iterations),
        ba_function_tolerance=max(config.ba_function_tolerance, merge_config.global_function_tolerance),
        num_threads=merge_config.num_threads,
    )
    odometry = {view.name: view.world_from_ego for task in tasks for view in task.views}
    seeds = (
        [model_seeds(m.reconstruction, a.world_from_clip) for m, a in zip(models, alignments, strict=True)]
        if merge_config.seed_from_clips
        else []
    )
    result = reconstruct_views(
        union,
        database,
        image_dir,
        merged_config,
        progress=_phase_reporter(progress, "merge"),
        odometry=odometry,
        seeds=seeds,
    )
    merge = {
        "groups": merge_groups(alignments),
        "alignments": {a.scene: a.to_json() for a in alignments},
        "height_ties_before_alignment": {scene: tie.to_json() for scene, tie in first_ties.items()},
        "height_ties": {scene: tie.to_json() for scene, tie in ties.items()},
    }
    return result, union, merge


def _flagged_views(
    outcomes: list[ClipOutcome], tasks: list[ClipTask], merged: GuidedResult, union: list[CameraView]
) -> tuple[CameraView, ...]:
    """Views dropped by their clip's BA (clip input pose) or by the merged BA (aligned pose)."""
    flagged = [
        v for o, t in zip(outcomes, tasks, strict=True) if o.ok for v in t.views if v.name in set(o.flagged)
    ]
    dropped = set(merged.flagged)
    return tuple(flagged + [v for v in union if v.name in dropped])


def reconstruct_site(
    clips: dict[str, list[CameraView]],
    database: Path,
    image_dir: Path,
    config: SfmConfig,
    clips_dir: Path,
    *,
    executor: Executor,
    merge_config: MergeConfig | None = None,
    progress: StageProgress | None = None,
    free_height: Collection[str] = (),
) -> SiteReconstruction:
    """Parallel per-clip reconstruction, then the merge (clip models are kept in `clips_dir/<scene>/`);
    `free_height`: the scenes whose heights WIGO left free (`merge_site`)."""
    started = time.perf_counter()
    tasks = _clip_tasks(clips, database, image_dir, config, clips_dir)
    outcomes = run_clips(tasks, executor, progress)
    clipped = time.perf_counter()
    result, union, merge = merge_site(
        outcomes, tasks, config, merge_config or MergeConfig(), progress, free_height
    )
    ended = time.perf_counter()
    report = {
        "executor": executor.name,
        "workers": executor.workers,
        "clips": {
            o.scene: {
                "status": "ok" if o.ok else "failed",
                "error": o.error,
                **o.report,
                "seconds": o.seconds,
            }
            for o in outcomes
        },
        "merge": merge,
        "merged": {**_summary(result, len(union)), "seconds": ended - clipped},
        "seconds": {"clips": clipped - started, "merge": ended - clipped, "total": ended - started},
    }
    views = tuple(refined_views(result, union))
    return SiteReconstruction(
        result.reconstruction, views, _flagged_views(outcomes, tasks, result, union), report, tuple(outcomes)
    )


def _pose_entries(site: SiteReconstruction) -> dict[str, PoseEntry]:
    """poses.json entries: refined registered views, then the flagged ones with their incoming pose."""
    entries = {}
    for flagged, views in ((False, site.views), (True, site.flagged)):
        for v in views:
            entries[v.token] = PoseEntry(v.name, v.scene, v.channel, v.world_from_ego, flagged)
    return entries


def write_site(
    workspace: Workspace,
    site_id: str,
    digest: str,
    site: SiteReconstruction,
    read_mask: MaskReader,
    extra: dict[str, Any],
) -> dict[str, Any]:
    """Write the site's model, poses, points and (last) report; returns the report."""
    write_model(workspace.sfm_model(site_id), site.reconstruction)
    write_poses(workspace.sfm_poses(site_id), site_id=site_id, digest=digest, poses=_pose_entries(site))
    write_points(workspace.sfm_points(site_id), sparse_points(site.reconstruction, read_mask))
    report = {"site_id": site_id, "fingerprint": digest, **extra, **site.report}
    return write_report(workspace.sfm_report(site_id), report)


def run_site(
    dataset: Dataset,
    workspace: Workspace,
    site_id: str,
    config: SfmConfig,
    *,
    executor: Executor,
    merge_config: MergeConfig,
    masks: MaskChoice | str = "auto",
    overwrite: bool = False,
    show_progress: bool = True,
) -> ItemResult:
    """Reconstruct one site into `sfm/<site_id>/` unless its outputs are up to date; its item: that folder and
    the site's report. `masks`: the choice `dataset.mask_roots` came from (the points' labels read them)."""
    manifest_path = workspace.site_manifest(site_id)
    database = workspace.features_db(site_id)
    if not database.is_file():
        raise FileNotFoundError(f"{database}: not found; run `cama features` first")
    folder, report_path = workspace.sfm_dir(site_id), workspace.sfm_report(site_id)
    features = stored_fingerprint(workspace.features_report(site_id)) or file_stats([database])
    digest = fingerprint(
        code_version("cama_pipeline.sfm"),
        asdict(config),
        asdict(merge_config),
        file_stats([manifest_path]),
        features,
        masks_fingerprint(masks, dataset.mask_roots, dataset.root),
    )
    if not overwrite and is_up_to_date(report_path, digest):
        return ItemResult(site_id, folder, read_report(report_path), skipped=True)
    manifest = read_site_manifest(manifest_path)
    views = site_views(dataset, manifest)
    clips_dir = workspace.sfm_clips(site_id)
    shutil.rmtree(clips_dir, ignore_errors=True)  # no stale model of a clip that fails this time
    with (
        tempfile.TemporaryDirectory(prefix="cama-sfm-") as scratch,
        StageProgress("sfm", logger=logger, enabled=show_progress, transient=True) as progress,
    ):
        copy = copy_database(database, Path(scratch) / "database.db")
        site = reconstruct_site(
            site_clips(views, manifest),
            copy,
            dataset.root,
            config,
            clips_dir,
            executor=executor,
            merge_config=merge_config,
            progress=progress,
            free_height=free_height_scenes(workspace, [scene["scene"] for scene in manifest["scenes"]]),
        )
    extra = {"config": asdict(config), "merge_config": asdict(merge_config)}
    report = write_site(workspace, site_id, digest, site, dataset_masks(dataset, views), extra)
    merged = report["merged"]
    logger.info(
        "site %s: %d of %d images registered, %d points, %.2f px",
        site_id,
        merged["registered_images"],
        merged["images"],
        merged["points"],
        merged["reprojection_error_px"],
    )
    return ItemResult(site_id, folder, report, skipped=False)


def run(
    config: SfmConfig,
    dataset_root: Path,
    workspace: Path | Workspace | None = None,
    *,
    executor: str = "local",
    workers: int = 2,
    merge_config: MergeConfig | None = None,
    masks: MaskChoice | str = "auto",
    overwrite: bool = False,
    show_progress: bool = True,
) -> StageResult:
    """Reconstruct every site of the workspace (after `cama features`) on the named executor; the sparse
    points are labelled by the masks of `masks` (`cama_pipeline.data.masks`)."""
    started = time.perf_counter()
    ws = Workspace.resolve(workspace, Path(dataset_root))
    site_ids = read_site_ids(ws.sites_index())
    runner = make_executor(executor, workers)
    dataset = load_dataset(
        Path(dataset_root),
        mask_roots=mask_roots(masks, Path(dataset_root), ws),
        scenes=read_site_scenes(ws.sites_index()),
    )
    sites = tuple(
        run_site(
            dataset,
            ws,
            site_id,
            config,
            executor=runner,
            merge_config=merge_config or MergeConfig(),
            masks=masks,
            overwrite=overwrite,
            show_progress=show_progress,
        )
        for site_id in site_ids
    )
    return StageResult("sfm", ws, sites, time.perf_counter() - started)
