"""Segmenter speed (issue 23.6: <= 0.15 s per 512x288 image on one CPU core): each checkpoint's median seconds
per image on one torch thread, measured in turn in one run, repeated, with the ratio to the first (the baseline).

Each checkpoint runs as the segment stage runs it (`SegmentationNet.for_inference`: batch norms folded, weights
channels-last) and, in the same rounds, as training leaves it (`as_trained_seconds`, and the stage's ratio to it).

With `--flip-average` each checkpoint is also timed as the segment stage runs it with `flip_average` on (the mirror
image's probabilities averaged in, `SegmentConfig.flip_average`), in the same rounds.

With `--size WxH` the images are that size (default 512x288, the issue's; its target applies to that size only):
the network still runs `input_width_px` wide, so a larger image adds the resizing around it.

Usage: .venv/bin/python bench/segment_speed.py --checkpoint BASELINE_DIR --checkpoint OTHER_DIR
       [--rounds 3] [--flip-average] [--size 512x288] [--out bench/results/segment_speed.json]
Run it on an otherwise idle machine: the figures are wall-clock times.
"""

import argparse
import json
import platform
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
from segment import SECONDS_PER_IMAGE_TARGET  # bench/segment.py: this script's folder is on sys.path

from cama_pipeline.segment.checkpoint import load_checkpoint
from cama_pipeline.segment.network import parameter_count
from cama_pipeline.segment.train import cpu_seconds_per_image

RESULTS = Path(__file__).parent / "results"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--checkpoint", type=Path, action="append", required=True, help="first: the baseline")
    parser.add_argument("--rounds", type=int, default=3, help="rounds over the checkpoints (interleaved)")
    parser.add_argument("--flip-average", action="store_true", help="also time each with mirror averaging")
    parser.add_argument("--size", default="512x288", help="image width x height in pixels")
    parser.add_argument("--out", type=Path, default=RESULTS / "segment_speed.json")
    args = parser.parse_args()
    try:
        width, height = (int(v) for v in args.size.lower().split("x"))
    except ValueError:
        parser.error(f"--size must be WIDTHxHEIGHT in pixels, got {args.size!r}")
    size = {"width": width, "height": height}
    per_image = f"seconds_per_{width}x{height}_image"
    target = SECONDS_PER_IMAGE_TARGET if (width, height) == (512, 288) else None
    checkpoints = [load_checkpoint(path) for path in args.checkpoint]
    times: dict[str, list[float]] = {c.label: [] for c in checkpoints}
    trained: dict[str, list[float]] = {c.label: [] for c in checkpoints}
    flipped: dict[str, list[float]] = {c.label: [] for c in checkpoints}
    for _ in range(args.rounds):
        for checkpoint in checkpoints:
            times[checkpoint.label].append(cpu_seconds_per_image(checkpoint.net, width, height, repeats=15))
            trained[checkpoint.label].append(
                cpu_seconds_per_image(checkpoint.net, width, height, repeats=15, as_trained=True)
            )
            if args.flip_average:
                seconds = cpu_seconds_per_image(checkpoint.net, width, height, repeats=15, flip_average=True)
                flipped[checkpoint.label].append(seconds)
    median = {label: float(np.median(seconds)) for label, seconds in times.items()}
    median_trained = {label: float(np.median(seconds)) for label, seconds in trained.items()}
    baseline = median[checkpoints[0].label]

    def with_flip(label: str) -> dict[str, Any]:
        if not flipped[label]:
            return {}
        seconds = float(np.median(flipped[label]))
        return {
            "flip_average_seconds_rounds": flipped[label],
            "flip_average_seconds": round(seconds, 4),
            "flip_average_ratio_to_plain": round(seconds / median[label], 2),
            "flip_average_target_met": None if target is None else seconds <= target,
        }

    figures = {
        "checkpoints": {
            c.label: {
                "path": str(c.path),
                "digest": c.digest,
                "network": c.net.config.to_json(),
                "parameters": parameter_count(c.net),
                f"{per_image}_rounds": times[c.label],
                per_image: round(median[c.label], 4),
                "ratio_to_baseline": round(median[c.label] / baseline, 2),
                "target_met": None if target is None else median[c.label] <= target,
                "as_trained_seconds_rounds": trained[c.label],
                "as_trained_seconds": round(median_trained[c.label], 4),
                "ratio_to_as_trained": round(median[c.label] / median_trained[c.label], 2),
                **with_flip(c.label),
            }
            for c in checkpoints
        },
        "baseline": checkpoints[0].label,
        "image_size": size,
        "target_s": target,
        "command": "python bench/segment_speed.py " + " ".join(sys.argv[1:]),
        "machine": {"python": platform.python_version(), "time": time.strftime("%Y-%m-%d %H:%M")},
    }
    print(json.dumps(figures["checkpoints"], indent=1))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(figures, indent=1) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
