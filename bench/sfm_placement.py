"""Where the error of a finished `cama sfm` run comes from: the model's shape, its scale, or its placement on
the odometry (the gauge fit onto WIGO).

Reads the refined poses of the site's workspace (`cama sfm` output) and compares, against the true cameras:
the poses as written; the same shape at its true scale, placed by the rigid gauge fit onto WIGO; the *true*
shape placed by the rigid and by the scaled gauge fit (the bounds any model placed on WIGO this way has); and
each driving clip's scale to the truth (> 1: the model is too small; clips spanning under MIN_CLIP_SPAN_M,
such as a stationary one, have no scale to measure).

Usage: .venv/bin/python bench/sfm_placement.py [--site data/synthetic/default]
Adds the site's run to bench/results/sfm_placement.json.
"""

import argparse
import logging
import sys
from pathlib import Path
from typing import Any

import numpy as np

from cama_pipeline.cameras import CameraView
from cama_pipeline.io import atomic_write_json
from cama_pipeline.sfm.baseline import pose_errors
from cama_pipeline.sfm.config import SfmConfig
from cama_pipeline.sfm.gauge import fit_gauge
from cama_pipeline.sfm.io import read_refined_poses
from cama_pipeline.sfm.merge import robust_similarity
from cama_pipeline.workspace import Workspace

sys.path.insert(0, str(Path(__file__).parent))
from sfm import read_runs, site_inputs, true_world_from_cam  # noqa: E402

RESULTS = Path(__file__).parent / "results"
Poses = dict[str, np.ndarray]
MIN_CLIP_SPAN_M = 10.0


def scale_to(source: Poses, target: Poses) -> float:
    """Scale of the similarity that best maps the source positions onto the target ones."""
    names = sorted(set(source) & set(target))
    found = robust_similarity(
        np.array([source[n][:3, 3] for n in names]), np.array([target[n][:3, 3] for n in names]), 0.5
    )
    if found is None:
        raise SystemExit(
            "no similarity between the refined and the true poses: is the sfm output this site's?"
        )
    return float(found[0].scale)


def scaled(poses: Poses, scale: float) -> Poses:
    """The poses with their positions scaled about their mean."""
    centre = np.mean([pose[:3, 3] for pose in poses.values()], axis=0)
    out = {}
    for name, pose in poses.items():
        out[name] = pose.copy()
        out[name][:3, 3] = centre + scale * (pose[:3, 3] - centre)
    return out


def placed(ego: Poses, wigo_ego: Poses, views: dict[str, CameraView], fit_scale: bool) -> Poses:
    """Camera poses of `ego` after the pipeline's gauge fit onto WIGO (rigid, or scaled)."""
    fit = fit_gauge(ego, wigo_ego, SfmConfig().gauge_sigmas(), fit_scale=fit_scale)
    if fit is None:
        raise SystemExit("fewer than 3 poses shared with WIGO")
    return {name: fit.move_pose(pose) @ views[name].ego_from_cam for name, pose in ego.items()}


def row(poses: Poses, truth: Poses) -> dict[str, float]:
    errors = pose_errors(poses, truth)
    return {"position_cm": round(errors.position_cm, 2), "rotation_deg": round(errors.rotation_deg, 4)}


def measure(site: Path) -> dict[str, Any]:
    """The table for one site (see the module docstring)."""
    _, manifest, views = site_inputs(site, None)
    by_name = {view.name: view for view in views}
    truth = true_world_from_cam(site, views)
    refined = read_refined_poses(Workspace.for_dataset(site / "nuscenes").sfm_poses(manifest["site_id"]))
    ego = {view.name: refined[view.token] for view in views if view.token in refined}
    cameras = {name: pose @ by_name[name].ego_from_cam for name, pose in ego.items()}
    wigo_ego = {view.name: view.world_from_ego for view in views}
    true_ego = {name: truth[name] @ np.linalg.inv(by_name[name].ego_from_cam) for name in ego}
    model_scale = scale_to(cameras, truth)
    clips = {
        clip: {n: p for n, p in cameras.items() if by_name[n].scene == clip}
        for clip in sorted({view.scene for view in by_name.values()})
    }
    return {
        "images": len(ego),
        "rows": {
            "as_written": row(cameras, truth),
            "model_at_true_scale_rigid_gauge": row(
                placed(scaled(ego, model_scale), wigo_ego, by_name, False), truth
            ),
            "true_shape_rigid_gauge": row(placed(true_ego, wigo_ego, by_name, False), truth),
            "true_shape_scaled_gauge": row(placed(true_ego, wigo_ego, by_name, True), truth),
        },
        "model_scale_to_truth": round(model_scale, 6),
        "clip_scale_to_truth": {
            clip: round(scale_to(poses, truth), 6)
            for clip, poses in clips.items()
            if np.ptp([pose[:3, 3] for pose in poses.values()], axis=0).max() >= MIN_CLIP_SPAN_M
        },
    }


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--site", type=Path, default=Path("data/synthetic/default"))
    parser.add_argument("--out", type=Path, default=RESULTS / "sfm_placement.json")
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)
    result = {"command": " ".join(sys.argv), "site": str(args.site), **measure(args.site)}
    for name, figures in result["rows"].items():
        print(f"{name:34s} {figures['position_cm']:6.2f} cm {figures['rotation_deg']:.4f} deg")
    print("model scale to truth", result["model_scale_to_truth"], "clips", result["clip_scale_to_truth"])
    runs = read_runs(args.out)
    runs[args.site.name] = result
    atomic_write_json(args.out, {"runs": runs}, indent=1)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
