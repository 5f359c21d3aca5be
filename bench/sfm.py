"""SfM benchmark: incremental mapping vs odometry-guided SfM (plain BA, rigid BA, iterative BA) vs parallel
per-clip reconstruction + merge, on one synthetic site, in one run.

For each method: wall time, camera position error (cm) and rotation error (deg) against the generator's true
poses (`ground_truth/poses.json`), mean reprojection error, registered-image ratio, points. Guided methods are
measured in the global frame as they come out; incremental mapping has no global frame, so it is first moved
by the similarity that best maps its camera centres onto the true ones (this favours it). The WIGO poses the
guided methods start from are measured too, giving the accuracy gain; the speed ratio compares (e) with (a).

    (a) incremental   pycolmap.incremental_mapping on the same database and images
    (b) plain         guided triangulation from WIGO poses + BA of every image pose
    (c) rigid         + rigid (rig) BA: one pose per keyframe, extrinsics held
    (d) iterative     + iterative BA (Algorithm 1)
    (e) parallel      (d) per clip on a process pool, clips merged (similarity from shared points), then
                      re-triangulation and global BA of the merged model
    (f) no priors     (e) without WIGO's odometry and position priors in BA (do they help?)
    (g) previous      (e) as it was before the speed-up: every BA run to full tolerance, two merge passes
    (h) rigid gauge   (e) with the rigid gauge fit of before (`SfmConfig.gauge_fit_scale` off; results files
                      made before the switch have (e) rigid and "h_parallel_scale_gauge" scaled instead)
Guided models are placed in the global frame by the gauge fit to all their WIGO poses (`sfm.gauge`; a
similarity unless the row says rigid). Every guided row also gives "gauge_free" errors: after the best
similarity to the true cameras, as (a) is measured, i.e. the model's shape without the global placement it
inherits from odometry. Rows give wall and CPU seconds (this process and its workers): on a shared machine
compare CPU seconds.

Usage: .venv/bin/python bench/sfm.py [--site data/synthetic/default] [--scenes scene-0001 scene-0002]
       [--workers 2] [--methods abcdefg] [--incremental-timeout-s 900]
(a) runs on as many threads as (e) has workers; with --incremental-timeout-s COLMAP stops it after that
long, the row says "did not finish" (figures of its partial model) and the (e)/(a) ratio is a lower bound.
The site's workspace must hold `cama sites` / `cama pairs` output; missing features are computed first.
Adds the run to bench/results/sfm.json ({"runs": {"<preset>:<scenes>": {...}}}, each with its command line,
site and scenes), so several sites measured by separate commands add up in one file.
"""

import argparse
import json
import logging
import platform
import resource
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pycolmap

from cama_pipeline.cameras import CameraView, site_views
from cama_pipeline.data import Pose, load_dataset
from cama_pipeline.features.config import FeaturesConfig
from cama_pipeline.features.stage import run as run_features
from cama_pipeline.sfm.baseline import (
    PoseErrors,
    align_to_reference,
    aligned_poses,
    incremental_model,
    model_poses,
    pose_errors,
)
from cama_pipeline.sfm.config import SfmConfig
from cama_pipeline.sfm.executor import LocalExecutor
from cama_pipeline.sfm.guided import reconstruct_views
from cama_pipeline.sfm.merge import MergeConfig
from cama_pipeline.sfm.stage import copy_database, reconstruct_site, site_clips
from cama_pipeline.site.io import read_site_ids, read_site_manifest
from cama_pipeline.workspace import Workspace

RESULTS = Path(__file__).parent / "results"
logger = logging.getLogger("bench.sfm")


def true_world_from_cam(site: Path, views: list[CameraView]) -> dict[str, np.ndarray]:
    """True camera poses by image name."""
    truth = json.loads((site / "ground_truth" / "poses.json").read_text())
    return {
        v.name: Pose(
            np.asarray(truth[v.token]["translation"]), np.asarray(truth[v.token]["rotation"])
        ).matrix()
        @ v.ego_from_cam
        for v in views
    }


def cpu_seconds() -> float:
    """CPU time of this process and its finished children (the worker processes): on a shared machine the
    wall time depends on the other jobs, the CPU time much less."""
    usage = [resource.getrusage(who) for who in (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN)]
    return sum(u.ru_utime + u.ru_stime for u in usage)


def figures(
    errors: PoseErrors, model: pycolmap.Reconstruction | None, seconds: float, **extra: Any
) -> dict[str, Any]:
    """One method's row."""
    return {
        "seconds": round(seconds, 2),
        "position_cm": round(errors.position_cm, 2),
        "rotation_deg": round(errors.rotation_deg, 4),
        "position_cm_median": round(errors.position_cm_median, 2),
        "rotation_deg_median": round(errors.rotation_deg_median, 4),
        "registered_ratio": round(errors.registered_ratio, 4),
        "reprojection_error_px": round(model.compute_mean_reprojection_error(), 3) if model else None,
        "points": model.num_points3D() if model else 0,
        **extra,
    }


def gauge_free(model: pycolmap.Reconstruction, truth: dict[str, np.ndarray]) -> dict[str, float]:
    """Errors after the similarity that best fits the model's cameras to the true ones: the shape of the
    reconstruction without its global placement (how incremental mapping is measured)."""
    return gauge_free_poses(model_poses(model), truth)


def gauge_free_poses(world_from_cam: dict[str, np.ndarray], truth: dict[str, np.ndarray]) -> dict[str, float]:
    errors = pose_errors(aligned_poses(world_from_cam, truth), truth)
    return {"position_cm": round(errors.position_cm, 2), "rotation_deg": round(errors.rotation_deg, 4)}


def run_incremental(
    database: Path,
    image_dir: Path,
    views: list[CameraView],
    truth: dict[str, Any],
    timeout_s: int | None,
    threads: int,
) -> dict:
    """Row (a) on `threads` threads (as many as (e) has workers); with `timeout_s` COLMAP stops mapping
    after that long and the row says it did not finish (its time is then a lower bound, its errors and
    registered ratio those of the partial model)."""
    started, cpu = time.perf_counter(), cpu_seconds()
    model = incremental_model(
        database, image_dir, [v.name for v in views], num_threads=threads, max_seconds=timeout_s
    )
    seconds, cpu = time.perf_counter() - started, round(cpu_seconds() - cpu, 1)
    finished = timeout_s is None or seconds < timeout_s
    status = {"finished": finished, "timeout_s": timeout_s}
    if model is None:
        return figures(pose_errors({}, truth), None, seconds, cpu_seconds=cpu, **status)
    aligned = align_to_reference(model, {name: pose[:3, 3] for name, pose in truth.items()})
    return figures(
        pose_errors(model_poses(model), truth),
        model,
        seconds,
        cpu_seconds=cpu,
        aligned_to_truth=aligned,
        **status,
    )


def run_guided(preset: str, database: Path, image_dir: Path, views: list[CameraView], truth: dict) -> dict:
    started, cpu = time.perf_counter(), cpu_seconds()
    result = reconstruct_views(views, database, image_dir, SfmConfig.preset(preset))
    seconds, cpu = time.perf_counter() - started, round(cpu_seconds() - cpu, 1)
    model = result.reconstruction
    iterations = result.report.get("iterations")
    extra = {
        "cpu_seconds": cpu,
        "iterations": len(iterations) if isinstance(iterations, list) else iterations,
        "flagged": len(result.flagged),
        "gauge": result.report.get("gauge"),
        "seconds_split": result.report.get("seconds"),
        "gauge_free": gauge_free(model, truth),
    }
    return figures(pose_errors(model_poses(model), truth), model, seconds, **extra)


def run_parallel(
    clips: dict[str, list[CameraView]],
    database: Path,
    image_dir: Path,
    truth: dict,
    workers: int,
    scratch: Path,
    config: SfmConfig,
    merge_config: MergeConfig | None = None,
) -> dict:
    started, cpu = time.perf_counter(), cpu_seconds()
    site = reconstruct_site(
        clips,
        database,
        image_dir,
        config,
        scratch,
        executor=LocalExecutor(workers),
        merge_config=merge_config,
    )
    seconds = time.perf_counter() - started
    model = site.reconstruction
    extra = {
        "cpu_seconds": round(cpu_seconds() - cpu, 1),
        "workers": workers,
        "clips": {
            scene: {k: clip.get(k) for k in ("status", "registered_images", "seconds")}
            for scene, clip in site.report["clips"].items()
        },
        "merge": site.report["merge"],
        "seconds_split": site.report["seconds"],
        "gauge": site.report["merged"].get("gauge"),
        "gauge_free": gauge_free(model, truth),
    }
    return figures(pose_errors(model_poses(model), truth), model, seconds, **extra)


def site_inputs(site: Path, scenes: list[str] | None) -> tuple[Path, dict[str, Any], list[CameraView]]:
    """The first site's database (features computed when missing), manifest and keyframe views (only those
    of `scenes` when given: a stationary scene left out is simply not part of its clip)."""
    dataset_root = site / "nuscenes"
    workspace = Workspace.for_dataset(dataset_root)
    site_id = read_site_ids(workspace.sites_index())[0]
    if not workspace.features_db(site_id).is_file():
        logger.info("no features yet: running `cama features` on %s", workspace.root)
        run_features(FeaturesConfig(), dataset_root, workspace)
    manifest = read_site_manifest(workspace.site_manifest(site_id))
    views = site_views(load_dataset(dataset_root), manifest)
    if scenes:
        known = {view.scene for view in views}
        unknown = sorted(set(scenes) - known)
        if unknown:
            raise SystemExit(f"--scenes: {unknown} are not scenes of {site_id} ({sorted(known)})")
        views = [view for view in views if view.scene in scenes]
    return workspace.features_db(site_id), manifest, views


def print_table(rows: dict[str, dict[str, Any]]) -> None:
    """The figures as a table (a failed method prints its error)."""
    print(
        f"{'method':<12}{'seconds':>9}{'cpu s':>9}{'pos cm':>9}{'rot deg':>9}{'reproj px':>10}{'registered':>11}{'points':>8}"
    )
    for name, row in rows.items():
        if "error" in row:
            print(f"{name:<12}failed: {row['error']}")
            continue
        reprojection = row.get("reprojection_error_px")
        print(
            f"{name:<12}{row.get('seconds', 0):>9.1f}{row.get('cpu_seconds') or 0:>9.1f}{row['position_cm']:>9.2f}{row['rotation_deg']:>9.4f}"
            f"{reprojection if reprojection is not None else float('nan'):>10.3f}"
            f"{row['registered_ratio']:>11.3f}{row.get('points', 0):>8}"
        )
        if row.get("finished") is False:
            print(f"{'':<12}did not finish in {row['timeout_s']} s: figures of its partial model")


def guarded(name: str, measure: Callable[[], dict[str, Any]]) -> dict[str, Any]:
    """One method's row, or its error (a method that breaks must not lose the others' figures)."""
    logger.info("method %s", name)
    try:
        return measure()
    except Exception as err:  # noqa: BLE001 - recorded in the results, the run goes on
        logger.exception("method %s failed", name)
        return {"error": f"{type(err).__name__}: {err}"}


def measure_all(
    args: argparse.Namespace, save: Callable[[dict[str, dict[str, Any]], list[CameraView], dict], None]
) -> None:
    """Every asked method's row on the site (see the module docstring), in the order of `args.methods`;
    `save` gets the rows so far after each method (a long run killed late keeps what it measured)."""
    site_database, manifest, views = site_inputs(args.site, args.scenes)
    truth = true_world_from_cam(args.site, views)
    image_dir = args.site / "nuscenes"
    wigo = {v.name: v.world_from_cam for v in views}
    rows = {"wigo": figures(pose_errors(wigo, truth), None, 0.0, gauge_free=gauge_free_poses(wigo, truth))}
    clips = site_clips(views, manifest)
    with tempfile.TemporaryDirectory(prefix="bench-sfm-") as scratch_dir:
        scratch = Path(scratch_dir)
        database = copy_database(site_database, scratch / "database.db")
        methods: dict[str, Callable[[], dict[str, Any]]] = {
            "a_incremental": lambda: run_incremental(
                database, image_dir, views, truth, args.incremental_timeout_s, args.workers
            ),
            "b_plain": lambda: run_guided("plain", database, image_dir, views, truth),
            "c_rigid": lambda: run_guided("rigid", database, image_dir, views, truth),
            "d_iterative": lambda: run_guided("iterative", database, image_dir, views, truth),
            "e_parallel": lambda: run_parallel(
                clips, database, image_dir, truth, args.workers, scratch / "e", SfmConfig.preset("iterative")
            ),
            "f_parallel_no_priors": lambda: run_parallel(
                clips,
                database,
                image_dir,
                truth,
                args.workers,
                scratch / "f",
                SfmConfig.preset("iterative", odometry_priors=False),
            ),
            "h_parallel_rigid_gauge": lambda: run_parallel(
                clips,
                database,
                image_dir,
                truth,
                args.workers,
                scratch / "h",
                SfmConfig.preset("iterative", gauge_fit_scale=False),
            ),
            "g_parallel_previous_merge": lambda: run_parallel(
                clips,
                database,
                image_dir,
                truth,
                args.workers,
                scratch / "g",
                SfmConfig.preset("iterative", ba_function_tolerance=0.0),
                MergeConfig(global_max_iterations=2, global_function_tolerance=0.0),
            ),
        }
        save(rows, views, manifest)
        for letter in dict.fromkeys(args.methods):
            for key in (k for k in methods if k[0] == letter):
                rows[key] = guarded(key, methods[key])
                save(rows, views, manifest)


def _ratio(numerator: float | None, denominator: float | None) -> float | None:
    return round(numerator / denominator, 2) if numerator and denominator else None


def summarize(rows: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """Speed ratio (e) over (a), accuracy gain of (e) over WIGO, and whether the paper's goal is met."""
    wigo, parallel, incremental = rows["wigo"], rows.get("e_parallel", {}), rows.get("a_incremental", {})
    if "seconds" not in parallel:
        return {"error": "parallel reconstruction failed or not run"}
    return {
        "speedup_e_over_a": round(incremental["seconds"] / parallel["seconds"], 2)
        if "seconds" in incremental
        else None,
        "speedup_is_lower_bound": incremental.get("finished") is False,
        "cpu_speedup_e_over_a": _ratio(incremental.get("cpu_seconds"), parallel.get("cpu_seconds")),
        "cpu_speedup_e_over_g_previous": _ratio(
            rows.get("g_parallel_previous_merge", {}).get("cpu_seconds"), parallel.get("cpu_seconds")
        ),
        "position_gain_over_wigo": round(wigo["position_cm"] / parallel["position_cm"], 2),
        "rotation_gain_over_wigo": round(wigo["rotation_deg"] / parallel["rotation_deg"], 2),
        "goal_met": parallel["position_cm"] <= 5 and parallel["rotation_deg"] <= 0.1,
    }


def site_preset(site: Path) -> dict[str, Any]:
    """The generator preset and seed of a synthetic site (so the measured site can be made again)."""
    try:
        manifest = json.loads((site / "manifest.json").read_text())
    except (OSError, ValueError):
        return {}
    return {"preset": manifest.get("preset"), "seed": manifest.get("seed")}


def read_runs(path: Path) -> dict[str, Any]:
    """Runs already in the results file (one per site and scene set), so sites measured apart add up."""
    try:
        runs = json.loads(path.read_text()).get("runs", {})
    except (OSError, ValueError, AttributeError):
        return {}
    return runs if isinstance(runs, dict) else {}


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--site", type=Path, default=Path("data/synthetic/default"))
    parser.add_argument("--scenes", nargs="*", help="Only the images of these scenes of the first site.")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument(
        "--methods",
        default="abcdefg",
        help="Letters of the methods to run, in this order (default all; e is always needed).",
    )
    parser.add_argument(
        "--incremental-timeout-s",
        type=int,
        default=None,
        help="Stop (a) incremental mapping after this long; it is then reported as not finished and the "
        "(e)/(a) speed ratio as a lower bound.",
    )
    parser.add_argument("--out", type=Path, default=RESULTS / "sfm.json")
    args = parser.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    pycolmap.logging.minloglevel = 2
    measure_all(args, lambda rows, views, manifest: save_run(args, rows, views, manifest))


def save_run(
    args: argparse.Namespace, rows: dict[str, dict[str, Any]], views: list[CameraView], manifest: dict
) -> None:
    """Print the rows so far and add them as this run into the results file."""
    print_table(rows)
    summary = summarize(rows)
    print(json.dumps(summary))
    scenes = args.scenes or sorted(site_clips(views, manifest))
    result = {
        "command": " ".join([Path(sys.executable).name, *sys.argv]),
        "machine": f"{platform.processor() or platform.machine()}, {platform.system()}, shared by other jobs",
        "site": str(args.site),
        "site_preset": site_preset(args.site),
        "scenes": scenes,
        "images": len(views),
        "methods": rows,
        "summary": summary,
    }
    key = f"{site_preset(args.site).get('preset') or args.site.name}:{','.join(scenes)}"
    runs = read_runs(args.out)
    runs[key] = result
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({"runs": runs}, indent=1))
    print(f"wrote run {key!r} into {args.out}")


if __name__ == "__main__":
    main()
