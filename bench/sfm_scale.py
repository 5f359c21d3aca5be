"""Scale of guided SfM clip models against the truth: is the model too small or too large, and does it come
from the odometry or from the images?

One clip of a synthetic site, reconstructed by `reconstruct_views` (the iterative preset) with config variants,
each from the WIGO poses and again from the TRUE poses (odometry exact: what is left comes from the images).
For each: the scale of the similarity that maps the model's camera centres onto the true ones (> 1: the model
is too small), and the position / rotation errors. Then, from the true poses, which points set the scale:
after Algorithm 1 only the points whose mean depth over their track is under (or at least) NEAR_DEPTH_M are
kept and the model is adjusted again.

Usage: .venv/bin/python bench/sfm_scale.py [--site data/synthetic/default] [--scene scene-0002]
Writes bench/results/sfm_scale.json.
"""

import argparse
import dataclasses
import logging
import platform
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pycolmap

from cama_pipeline.cameras import CameraView
from cama_pipeline.io import atomic_write_json
from cama_pipeline.sfm.baseline import model_poses, pose_errors
from cama_pipeline.sfm.bundle import bundle_adjust
from cama_pipeline.sfm.config import SfmConfig
from cama_pipeline.sfm.guided import reconstruct_views
from cama_pipeline.sfm.iterative import iterative_bundle_adjustment
from cama_pipeline.sfm.merge import robust_similarity
from cama_pipeline.sfm.model import build_model
from cama_pipeline.sfm.stage import copy_database
from cama_pipeline.sfm.triangulate import triangulate_all

sys.path.insert(0, str(Path(__file__).parent))
from sfm import site_inputs, true_world_from_cam  # noqa: E402

RESULTS = Path(__file__).parent / "results"
VARIANTS: dict[str, dict[str, Any]] = {
    "default": {},
    "no_odometry_priors": {"odometry_priors": False},
    "no_robust_loss": {"loss": "trivial"},
    "refined_extrinsics": {"refine_extrinsics": True},
}
NEAR_DEPTH_M = 15.0
SUBSETS: dict[str, Callable[[float], bool]] = {
    "all_points": lambda depth: True,
    f"near_points_under_{NEAR_DEPTH_M:g}m": lambda depth: depth < NEAR_DEPTH_M,
    f"far_points_from_{NEAR_DEPTH_M:g}m": lambda depth: depth >= NEAR_DEPTH_M,
}


def on_true_poses(views: list[CameraView], truth: dict[str, np.ndarray]) -> list[CameraView]:
    """The views with their ego poses replaced by the true ones."""
    return [
        dataclasses.replace(view, world_from_ego=truth[view.name] @ np.linalg.inv(view.ego_from_cam))
        for view in views
    ]


def scale_row(
    reconstruction: pycolmap.Reconstruction, truth: dict[str, np.ndarray], started: float
) -> dict[str, Any]:
    """A model's scale to the truth and its errors, with the CPU seconds since `started`."""
    poses = model_poses(reconstruction)
    names = [name for name in poses if name in truth]
    found = robust_similarity(
        np.array([poses[n][:3, 3] for n in names]), np.array([truth[n][:3, 3] for n in names]), 0.5
    )
    errors = pose_errors(poses, truth)
    return {
        "scale_to_truth": round(float(found[0].scale), 6) if found else None,
        "position_cm": round(errors.position_cm, 2),
        "rotation_deg": round(errors.rotation_deg, 4),
        "images": len(names),
        "points": reconstruction.num_points3D(),
        "cpu_seconds": round(time.process_time() - started, 1),
    }


def measure(
    views: list[CameraView], database: Path, image_dir: Path, truth: dict[str, np.ndarray], overrides: dict
) -> dict[str, Any]:
    """One reconstruction's scale to the truth and errors; placed by the rigid gauge fit, so the scale is the
    one BA found (a scaled fit would take WIGO's)."""
    started = time.process_time()
    config = SfmConfig.preset("iterative", gauge_fit_scale=False, **overrides)
    result = reconstruct_views(views, database, image_dir, config)
    return scale_row(result.reconstruction, truth, started)


def mean_depth(reconstruction: pycolmap.Reconstruction, point: pycolmap.Point3D) -> float:
    """The point's mean depth over the images of its track, metres."""
    depths = [
        (reconstruction.image(element.image_id).cam_from_world() * point.xyz)[2]
        for element in point.track.elements
    ]
    return float(np.mean(depths))


def measure_subset(
    views: list[CameraView], database: Path, truth: dict[str, np.ndarray], keep: Callable[[float], bool]
) -> dict[str, Any]:
    """Algorithm 1 from these views' poses, then only the points whose mean depth `keep` accepts, adjusted
    again (two BA passes): the scale those points alone give."""
    started = time.process_time()
    config = SfmConfig.preset("iterative")
    with tempfile.TemporaryDirectory(prefix="bench-sfm-subset-") as work:
        model = build_model(views, database, Path(work), config)
        triangulate_all(model, config)
        iterative_bundle_adjustment(model, config, lambda phase, done, total: None)
        reconstruction = model.reconstruction
        dropped = [
            point_id
            for point_id, point in reconstruction.points3D.items()
            if not keep(mean_depth(reconstruction, point))
        ]
        for point_id in dropped:
            model.mapper.observation_manager.delete_point3D(point_id)
        for _ in range(2):
            bundle_adjust(model, config)
        return scale_row(reconstruction, truth, started)


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--site", type=Path, default=Path("data/synthetic/default"))
    parser.add_argument("--scene", default="scene-0002")
    parser.add_argument("--out", type=Path, default=RESULTS / "sfm_scale.json")
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)
    database, _, views = site_inputs(args.site, [args.scene])
    truth = true_world_from_cam(args.site, views)
    rows: dict[str, dict[str, Any]] = {}
    with tempfile.TemporaryDirectory(prefix="bench-sfm-scale-") as scratch:
        work = copy_database(database, Path(scratch) / "database.db")
        for start, start_views in (("wigo", views), ("true", on_true_poses(views, truth))):
            for name, overrides in VARIANTS.items():
                row = measure(start_views, work, args.site / "nuscenes", truth, overrides)
                rows[f"{start}/{name}"] = row
                print(f"from {start:5s} {name:20s} {row}", flush=True)
        true_views = on_true_poses(views, truth)
        for name, keep in SUBSETS.items():
            row = measure_subset(true_views, work, truth, keep)
            rows[f"true/{name}"] = row
            print(f"from true  {name:20s} {row}", flush=True)
    out = {
        "command": " ".join(sys.argv),
        "site": str(args.site),
        "scene": args.scene,
        "rows": rows,
        "machine": {"python": platform.python_version(), "platform": platform.platform()},
    }
    atomic_write_json(args.out, out, indent=1)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
