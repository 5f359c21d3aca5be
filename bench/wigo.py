"""Acceptance benchmark of WIGO, keyframes and sites on the default synthetic site.

Per clip, the position RMSE and heading RMSE against the ground truth (`ground_truth/poses.json`, used by
this bench only, never by the fusion) of:
  coarse     the logged `ego_pose` of every image;
  gnss       GNSS alone: fixes interpolated linearly to the image times, heading from the fixes' track;
  wheel_imu  wheel + gyro dead reckoning alone, started at the clip's first logged pose;
  wigo       the pose graph with its defaults (wheel + IMU + robust GNSS + logged pose);
  wigo_no_logged_pose  the pose graph without the logged pose (wheel + IMU + GNSS only), for reference.

GNSS cases (the data set has multipath outliers baked in):
  outliers_on   the fixes as recorded;
  outliers_off  the same fixes without the outliers, found here with the truth: a fix whose horizontal error
                exceeds max(4 m, 3 x its reported sigma) is removed (in memory; the data set is not touched);
  outliers_x5   the recorded fixes plus extra outliers on 10 % of them (8-20 m jumps, fixed seed).
Drift over the longest clip (by path length): mean position error of the last second minus the first.
Also written: keyframe counts per clip and the largest multi-view time difference after resync, and sites.

Usage: .venv/bin/python bench/wigo.py [--site data/synthetic/default]
Prints the figures and writes them to bench/results/wigo.json.
"""

import argparse
import json
import logging
import platform
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table
from scipy.spatial.transform import Rotation

from cama_pipeline.data import GnssSeries, Pose, Scene, load_dataset
from cama_pipeline.evaluate.errors import pose_errors
from cama_pipeline.evaluate.inputs import load_true_poses
from cama_pipeline.keyframes import KeyframeConfig
from cama_pipeline.keyframes import run as run_keyframes
from cama_pipeline.site.config import SiteConfig
from cama_pipeline.site.stage import run as run_sites
from cama_pipeline.wigo import ClipInputs, WigoConfig, clip_inputs, fuse_clip
from cama_pipeline.wigo import run as run_wigo
from cama_pipeline.wigo.fusion import graph_span
from cama_pipeline.wigo.odometry import dead_reckon, integration_grid

RESULTS = Path(__file__).parent / "results"
HEADING_FIXES = 10
"""GNSS-alone heading: the track direction of this many fixes nearest in time to the image (2 s at 5 Hz)."""
METHODS = ("coarse", "gnss", "wheel_imu", "wigo", "wigo_no_logged_pose")
console = Console()


def _poses(R: np.ndarray, t: np.ndarray) -> list[Pose]:
    quats = Rotation.from_matrix(R).as_quat(scalar_first=True)
    return [Pose(tt, q) for tt, q in zip(t, quats, strict=True)]


def true_positions_at(times_us: np.ndarray, cam_times: np.ndarray, cam_true: np.ndarray) -> np.ndarray:
    """True positions at `times_us`, linear in time, extrapolated from the first / last two images."""
    out = np.stack([np.interp(times_us, cam_times, cam_true[:, k]) for k in range(3)], axis=1)
    for side, (a, b) in (("lo", (0, 1)), ("hi", (-2, -1))):
        mask = times_us < cam_times[0] if side == "lo" else times_us > cam_times[-1]
        velocity = (cam_true[b] - cam_true[a]) / max((cam_times[b] - cam_times[a]) * 1e-6, 1e-6)
        anchor = a if side == "lo" else b
        out[mask] = cam_true[anchor] + np.outer((times_us[mask] - cam_times[anchor]) * 1e-6, velocity)
    return out


def gnss_cases(inputs: ClipInputs, truth: np.ndarray, rng: np.random.Generator) -> dict[str, GnssSeries]:
    """The recorded fixes, the fixes without outliers (found with the truth), and with extra outliers."""
    g = inputs.gnss
    assert g is not None
    true_at = true_positions_at(g.utime, inputs.cameras.times_us, truth)
    error = np.linalg.norm((g.pos_m - true_at)[:, :2], axis=1)
    clean = error <= np.maximum(4.0, 3.0 * g.std_m[:, 0])
    hit = rng.uniform(size=len(g.utime)) < 0.10
    angle = rng.uniform(0, 2 * np.pi, len(g.utime))
    jump = rng.uniform(8.0, 20.0, len(g.utime)) * hit
    stressed = g.pos_m + np.stack([jump * np.cos(angle), jump * np.sin(angle), np.zeros_like(jump)], 1)

    def subset(mask: np.ndarray, pos: np.ndarray) -> GnssSeries:
        return GnssSeries(g.utime[mask], pos[mask], g.std_m[mask], g.fix[mask])

    everything = np.ones(len(g.utime), bool)
    return {
        "outliers_on": g,
        "outliers_off": subset(clean, g.pos_m),
        "outliers_x5": subset(everything, stressed),
    }


def gnss_alone(gnss: GnssSeries, times_us: np.ndarray) -> list[Pose]:
    """Poses from GNSS only: positions interpolated, heading along the fixes' track, level attitude."""
    pos = np.stack([np.interp(times_us, gnss.utime, gnss.pos_m[:, k]) for k in range(3)], axis=1)
    yaw = np.zeros(len(times_us))
    for i, t in enumerate(times_us):
        # direction of the principal axis of the HEADING_FIXES fixes nearest in time, pointing along time
        near = np.argsort(np.abs(gnss.utime - t), kind="stable")[:HEADING_FIXES]
        if len(near) >= 2:
            xy = gnss.pos_m[near, :2] - gnss.pos_m[near, :2].mean(axis=0)
            axis = np.linalg.svd(xy, full_matrices=False)[2][0]
            dt = (gnss.utime[near] - t).astype(float)
            axis *= np.sign(np.dot(xy.T @ dt, axis)) or 1.0
            yaw[i] = np.arctan2(axis[1], axis[0])
    R = Rotation.from_euler("z", yaw[:, None]).as_matrix()
    return _poses(R, pos)


def wheel_imu_alone(inputs: ClipInputs, config: WigoConfig) -> list[Pose]:
    """Dead reckoning only, started at the first image's logged pose."""
    cam = inputs.cameras
    start, stop = graph_span(inputs, config)
    grid = integration_grid(start, stop, cam.times_us, config.integration_rate_hz)
    odo = dead_reckon(inputs, grid, config)
    index = np.searchsorted(grid, cam.times_us)
    R0, t0 = cam.rotation[0], cam.translation[0]
    first = index[0]
    rel_R = np.swapaxes(odo.rotation[first], 0, 1) @ odo.rotation[index]
    rel_t = (odo.translation[index] - odo.translation[first]) @ odo.rotation[first]
    return _poses(R0 @ rel_R, t0 + rel_t @ R0.T)


def clip_figures(scene: Scene, truth_poses: dict[str, Pose], rng: np.random.Generator) -> dict[str, object]:
    """All methods and GNSS cases of one clip."""
    inputs = clip_inputs(scene)
    truth = [truth_poses[t] for t in inputs.cameras.tokens]
    truth_t = np.array([p.translation for p in truth])
    config, no_logged = WigoConfig(), WigoConfig(logged_pose_sigmas=(0.0, 0.0, 0.0, 0.0))
    out: dict[str, object] = {
        "images": len(truth),
        "path_length_m": float(np.linalg.norm(np.diff(truth_t, axis=0), axis=1).sum()),
    }
    for case, gnss in gnss_cases(inputs, truth_t, rng).items():
        case_inputs = replace(inputs, gnss=gnss)
        wigo = fuse_clip(case_inputs, config)
        wigo_plain = fuse_clip(case_inputs, no_logged)
        estimates = {
            "coarse": _poses(inputs.cameras.rotation, inputs.cameras.translation),
            "gnss": gnss_alone(gnss, inputs.cameras.times_us),
            "wheel_imu": wheel_imu_alone(inputs, config),
            "wigo": _poses(wigo.rotation, wigo.translation),
            "wigo_no_logged_pose": _poses(wigo_plain.rotation, wigo_plain.translation),
        }
        rows: dict[str, object] = {
            "gnss_fixes": len(gnss.utime),
            "wigo_gnss_downweighted": wigo.report["gnss_downweighted"],
        }
        for method, est in estimates.items():
            err = pose_errors(est, truth)
            position = np.linalg.norm(np.array([p.translation for p in est]) - truth_t, axis=1)
            seconds = (inputs.cameras.times_us - inputs.cameras.times_us[0]) * 1e-6
            first, last = seconds <= 1.0, seconds >= seconds[-1] - 1.0
            rows[method] = {
                "position_rmse_m": round(err.position_rmse_m, 4),
                "heading_rmse_deg": round(err.heading_rmse_deg, 4),
                "drift_m": round(float(position[last].mean() - position[first].mean()), 4),
                "end_error_m": round(float(position[last].mean()), 4),
            }
        rows["wigo_best_position"] = all(
            rows["wigo"]["position_rmse_m"] <= rows[m]["position_rmse_m"]
            for m in ("coarse", "gnss", "wheel_imu")  # type: ignore[index]
        )
        rows["wigo_best_heading"] = all(
            rows["wigo"]["heading_rmse_deg"] <= rows[m]["heading_rmse_deg"]
            for m in ("coarse", "gnss", "wheel_imu")  # type: ignore[index]
        )
        out[case] = rows
    return out


def stage_figures(site: Path) -> dict[str, object]:
    """Run the three stages into a temporary workspace; keyframe counts, time differences and sites."""
    with tempfile.TemporaryDirectory() as tmp:
        root = site / "nuscenes"
        started = time.perf_counter()
        run_wigo(WigoConfig(), root, Path(tmp), show_progress=False)
        wigo_s = time.perf_counter() - started
        kf_result = run_keyframes(KeyframeConfig(), root, Path(tmp))
        keyframes = {}
        for item in kf_result.items:
            kf = item.report
            keyframes[item.name] = {
                "frames": kf["frames"],
                "keyframes": kf["keyframes"],
                "stationary": kf["stationary"],
                "path_length_m": round(kf["path_length_m"], 1),
                "max_time_diff_ms": kf["max_time_diff_us"] / 1000,
                "max_time_range_ms": kf["max_time_range_us"] / 1000,
            }
        sites = run_sites(SiteConfig(), root, Path(tmp))
    return {
        "wigo_stage_seconds": round(wigo_s, 2),
        "keyframes": keyframes,
        "sites": sites.report["sites"],
        "dropped": {entry["scene"]: entry["reason"] for entry in sites.report["dropped"]},
    }


def print_table(clips: dict[str, dict]) -> None:
    for case in ("outliers_on", "outliers_off", "outliers_x5"):
        table = Table(title=f"ATE vs ground truth, GNSS {case}: position RMSE m / heading RMSE deg")
        table.add_column("clip")
        for method in METHODS:
            table.add_column(method)
        for name, figures in clips.items():
            rows = figures[case]
            table.add_row(
                name,
                *(f"{rows[m]['position_rmse_m']:.3f} / {rows[m]['heading_rmse_deg']:.3f}" for m in METHODS),
            )
        console.print(table)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--site", type=Path, default=Path("data/synthetic/default"))
    parser.add_argument("--out", type=Path, default=RESULTS / "wigo.json")
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)
    dataset = load_dataset(args.site / "nuscenes", check_files=False)
    truth = load_true_poses(args.site / "ground_truth" / "poses.json")
    rng = np.random.default_rng(2024)
    started = time.perf_counter()
    clips = {
        scene.name: {"description": scene.description, **clip_figures(scene, truth, rng)}
        for scene in dataset.scenes
    }
    longest = max(clips, key=lambda n: clips[n]["path_length_m"])
    figures: dict[str, object] = {
        "site": str(args.site),
        "clips": clips,
        "longest_clip": longest,
        "longest_clip_drift_m": {m: clips[longest]["outliers_on"][m]["drift_m"] for m in METHODS},
        **stage_figures(args.site),
        "seconds": round(time.perf_counter() - started, 1),
        "machine": {"python": platform.python_version()},
    }
    print_table(clips)
    console.print(
        f"longest clip {longest}: drift (last s - first s mean position error) {figures['longest_clip_drift_m']}"
    )
    for name, kf in figures["keyframes"].items():  # type: ignore[attr-defined]
        console.print(f"keyframes {name}: {kf}")
    console.print(f"sites: {figures['sites']}; dropped: {figures['dropped']}")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(figures, indent=1) + "\n")
    console.print(f"written {args.out}")


if __name__ == "__main__":
    main()
