"""Benchmark the synthetic generator: throughput (images/s, megapixels/s) and a realism figure.

Usage: .venv/bin/python bench/synth.py [--preset default] [--workers 2] [--out DIR]
Prints the figures and writes them to bench/results/synth_<preset>.json.
"""

import argparse
import json
import os
import platform
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

from cama_pipeline.data import load_dataset
from cama_pipeline.synthetic.config import preset
from cama_pipeline.synthetic.generate import run

RESULTS = Path(__file__).parent / "results"


def road_sift_inliers(dataset_root: Path, pairs: int = 10) -> list[int]:
    """Fundamental-matrix inlier SIFT matches on road pixels between CAM_FRONT sweeps 2 apart (first day scene)."""
    scene = next(s for s in load_dataset(dataset_root).scenes if s.description.startswith("Day, moving"))
    images = scene.images["CAM_FRONT"]
    sift = cv2.SIFT_create()
    counts = []
    for a, b in list(zip(images, images[2:], strict=False))[:pairs]:
        kp_a, des_a = sift.detectAndCompute(cv2.cvtColor(a.load_rgb(), cv2.COLOR_RGB2GRAY), None)
        kp_b, des_b = sift.detectAndCompute(cv2.cvtColor(b.load_rgb(), cv2.COLOR_RGB2GRAY), None)
        good = [m for m, n in cv2.BFMatcher().knnMatch(des_a, des_b, k=2) if m.distance < 0.8 * n.distance]
        pa = np.float32([kp_a[m.queryIdx].pt for m in good])
        pb = np.float32([kp_b[m.trainIdx].pt for m in good])
        _, inlier = cv2.findFundamentalMat(pa, pb, cv2.FM_RANSAC, 1.0, 0.999)
        semantic = a.load_semantic()
        on_road = np.isin(semantic[pa[:, 1].astype(int), pa[:, 0].astype(int)], [1, 2, 3, 4])
        counts.append(int((inlier.ravel().astype(bool) & on_road).sum()))
    return counts


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--preset", default="default")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--out", type=Path, default=None, help="site folder (a temporary one when omitted)")
    args = parser.parse_args()
    cfg = preset(args.preset)
    with tempfile.TemporaryDirectory() as tmp:
        out = args.out or Path(tmp) / args.preset
        started = time.perf_counter()
        result = run(cfg, out, overwrite=True, workers=args.workers)
        seconds = time.perf_counter() - started
        megapixels = result.images * cfg.camera.width_px * cfg.camera.height_px / 1e6
        inliers = road_sift_inliers(result.dataset_root)
    figures = {
        "preset": args.preset,
        "workers": args.workers,
        "image_size": [cfg.camera.width_px, cfg.camera.height_px],
        "images": result.images,
        "scenes": len(result.scenes),
        "seconds": round(seconds, 1),
        "images_per_s": round(result.images / seconds, 2),
        "megapixels_per_s": round(megapixels / seconds, 3),
        "road_sift_inliers_median": float(np.median(inliers)),
        "road_sift_inliers_min": int(min(inliers)),
        "machine": {"cpus": os.cpu_count(), "python": platform.python_version()},
    }
    for key, value in figures.items():
        print(f"{key:>26}: {value}")
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / f"synth_{args.preset}.json").write_text(json.dumps(figures, indent=2) + "\n")


if __name__ == "__main__":
    main()
