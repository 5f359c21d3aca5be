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

import numpy as np

from cama_pipeline.data import load_dataset
from cama_pipeline.synthetic.config import preset
from cama_pipeline.synthetic.generate import run
from cama_pipeline.synthetic.realism import road_sift_inliers

RESULTS = Path(__file__).parent / "results"


def road_matches(dataset_root: Path, pairs: int = 12) -> list[int]:
    """Verified road SIFT matches between CAM_FRONT sweeps 2 apart (about 1.3 m), over the first day scene."""
    scene = next(s for s in load_dataset(dataset_root).scenes if s.description.startswith("Day, moving"))
    images = scene.images["CAM_FRONT"]
    step = max(1, (len(images) - 2) // pairs)
    return [
        road_sift_inliers(a.load_rgb(), b.load_rgb(), a.load_semantic())
        for a, b in list(zip(images, images[2:], strict=False))[::step][:pairs]
    ]


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
        inliers = road_matches(result.dataset_root)
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
