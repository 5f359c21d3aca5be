"""WIGO without GNSS on logged poses that carry no height, as real nuScenes' (its localization is 2D: "z is always 0").

For every clip of a synthetic site the GNSS fixes are dropped and the logged ego poses' z set to 0 (in memory; the
data set is not touched), and the clip is fused three ways in one run:
  logged_3d      the logged poses as the generator wrote them (heights included): the reference;
  flat_fused     z = 0 fused as a height (`free_flat_logged_height = false`: WIGO before it);
  flat_free      z = 0 left free (`free_flat_logged_height = true`, the default): heights from wheels and IMU.
Scored against the true poses (`ground_truth/poses.json`, used by this bench only) per clip: the vertical RMSE
after removing the clip's median height offset (no measurement without GNSS or a logged height fixes the absolute
height; the ego-frame exports and the surface read heights relative to the poses), the largest such error, the
pitch RMSE of the ego poses, and the horizontal RMSE. Also the clip's true height range (how much it climbs).

Usage: .venv/bin/python bench/wigo_flat_height.py [--site data/synthetic/default]
       [--out bench/results/wigo_flat_height.json]
"""

import argparse
import platform
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from cama_pipeline.data import load_dataset
from cama_pipeline.evaluate.inputs import load_true_poses
from cama_pipeline.io import atomic_write_json
from cama_pipeline.wigo import ClipInputs, WigoConfig, clip_inputs, fuse_clip

RESULTS = Path(__file__).parent / "results"
VARIANTS = ("logged_3d", "flat_fused", "flat_free")


def flat_inputs(inputs: ClipInputs) -> ClipInputs:
    """The clip without GNSS and with every logged z set to 0."""
    translation = inputs.cameras.translation.copy()
    translation[:, 2] = 0.0
    return replace(inputs, gnss=None, cameras=replace(inputs.cameras, translation=translation))


def pitch_deg(rotation: np.ndarray) -> np.ndarray:
    """(N,) pitch of global_from_ego rotations: the forward axis' elevation above the horizontal plane."""
    forward = rotation[:, :, 0]
    return np.degrees(np.arcsin(np.clip(forward[:, 2], -1.0, 1.0)))


def clip_figures(inputs: ClipInputs, truth: dict[str, Any]) -> dict[str, Any]:
    """The three fusions of one clip (see the module docstring), scored against the truth."""
    true_t = np.array([truth[t].translation for t in inputs.cameras.tokens])
    true_R = np.array([truth[t].matrix()[:3, :3] for t in inputs.cameras.tokens])
    flat = flat_inputs(inputs)
    fused = {
        "logged_3d": fuse_clip(replace(inputs, gnss=None), WigoConfig()),
        "flat_fused": fuse_clip(flat, WigoConfig(free_flat_logged_height=False)),
        "flat_free": fuse_clip(flat, WigoConfig()),
    }
    figures: dict[str, Any] = {
        "images": len(true_t),
        "true_height_range_m": float(np.ptp(true_t[:, 2])),
    }
    for name, poses in fused.items():
        vertical = poses.translation[:, 2] - true_t[:, 2]
        vertical = vertical - np.median(vertical)
        horizontal = np.linalg.norm(poses.translation[:, :2] - true_t[:, :2], axis=1)
        pitch = pitch_deg(poses.rotation) - pitch_deg(true_R)
        figures[name] = {
            "vertical_rmse_m": float(np.sqrt(np.mean(vertical**2))),
            "vertical_max_m": float(np.max(np.abs(vertical))),
            "pitch_rmse_deg": float(np.sqrt(np.mean(pitch**2))),
            "horizontal_rmse_m": float(np.sqrt(np.mean(horizontal**2))),
            "logged_pose_height": poses.report.get("logged_pose_height"),
        }
    return figures


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--site", type=Path, default=Path("data/synthetic/default"))
    parser.add_argument("--out", type=Path, default=RESULTS / "wigo_flat_height.json")
    args = parser.parse_args()
    dataset = load_dataset(args.site / "nuscenes", check_files=False)
    truth = load_true_poses(args.site / "ground_truth" / "poses.json")
    clips = {scene.name: clip_figures(clip_inputs(scene), truth) for scene in dataset.scenes}
    for name, clip in clips.items():
        cells = ", ".join(
            f"{v} {clip[v]['vertical_rmse_m'] * 100:.1f} cm (max {clip[v]['vertical_max_m'] * 100:.1f}), "
            f"pitch {clip[v]['pitch_rmse_deg']:.2f} deg"
            for v in VARIANTS
        )
        print(f"{name} (climbs {clip['true_height_range_m']:.2f} m): {cells}")
    summary = {
        v: {
            key: float(np.sqrt(np.mean([c[v][key] ** 2 for c in clips.values()])))
            for key in ("vertical_rmse_m", "pitch_rmse_deg", "horizontal_rmse_m")
        }
        for v in VARIANTS
    }
    results = {
        "command": " ".join([sys.executable.split("/")[-1], *sys.argv]),
        "site": str(args.site),
        "machine": {"platform": platform.platform()},
        "clips": clips,
        "all_clips_rms": summary,
    }
    atomic_write_json(args.out, results, indent=1)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
