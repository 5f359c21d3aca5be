"""Scale of guided SfM clip models against the truth: is the model too small or too large, and does it come
from the odometry or from the images?

One clip of a synthetic site, reconstructed by `reconstruct_views` (the iterative preset) with config variants,
each from the WIGO poses and again from the TRUE poses (odometry exact: what is left comes from the images).
For each: the scale of the similarity that maps the model's camera centres onto the true ones (> 1: the model
is too small), and the position / rotation errors.

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
from pathlib import Path
from typing import Any

import numpy as np

from cama_pipeline.io import atomic_write_json
from cama_pipeline.pairs.cameras import CameraView
from cama_pipeline.sfm.baseline import model_poses, pose_errors
from cama_pipeline.sfm.config import SfmConfig
from cama_pipeline.sfm.guided import reconstruct_views
from cama_pipeline.sfm.merge import robust_similarity
from cama_pipeline.sfm.stage import copy_database

sys.path.insert(0, str(Path(__file__).parent))
from sfm import site_inputs, true_world_from_cam  # noqa: E402

RESULTS = Path(__file__).parent / "results"
VARIANTS: dict[str, dict[str, Any]] = {
    "default": {},
    "no_odometry_priors": {"odometry_priors": False},
    "no_robust_loss": {"loss": "trivial"},
    "refined_extrinsics": {"refine_extrinsics": True},
}


def on_true_poses(views: list[CameraView], truth: dict[str, np.ndarray]) -> list[CameraView]:
    """The views with their ego poses replaced by the true ones."""
    return [
        dataclasses.replace(view, world_from_ego=truth[view.name] @ np.linalg.inv(view.ego_from_cam))
        for view in views
    ]


def measure(
    views: list[CameraView], database: Path, image_dir: Path, truth: dict[str, np.ndarray], overrides: dict
) -> dict[str, Any]:
    """One reconstruction's scale to the truth and errors."""
    started = time.process_time()
    result = reconstruct_views(views, database, image_dir, SfmConfig.preset("iterative", **overrides))
    poses = model_poses(result.reconstruction)
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
        "cpu_seconds": round(time.process_time() - started, 1),
    }


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
