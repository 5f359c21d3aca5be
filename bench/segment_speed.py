"""Segmenter speed (issue 23.6: <= 0.15 s per 512x288 image on one CPU core): each checkpoint's median seconds
per image on one torch thread, measured in turn in one run, repeated, with the ratio to the first (the baseline).

Each checkpoint runs as the segment stage runs it (`SegmentationNet.for_inference`: batch norms folded, weights
channels-last) and, in the same rounds, as training leaves it (`as_trained_seconds`, and the stage's ratio to it).

With `--flip-average` each checkpoint is also timed as the segment stage runs it with `flip_average` on (the mirror
image's probabilities averaged in, `SegmentConfig.flip_average`), in the same rounds.

Usage: .venv/bin/python bench/segment_speed.py --checkpoint BASELINE_DIR --checkpoint OTHER_DIR
       [--rounds 3] [--flip-average] [--out bench/results/segment_speed.json]
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
    parser.add_argument("--out", type=Path, default=RESULTS / "segment_speed.json")
    args = parser.parse_args()
    checkpoints = [load_checkpoint(path) for path in args.checkpoint]
    times: dict[str, list[float]] = {c.label: [] for c in checkpoints}
    trained: dict[str, list[float]] = {c.label: [] for c in checkpoints}
    flipped: dict[str, list[float]] = {c.label: [] for c in checkpoints}
    for _ in range(args.rounds):
        for checkpoint in checkpoints:
            times[checkpoint.label].append(cpu_seconds_per_image(checkpoint.net, repeats=15))
            trained[checkpoint.label].append(
                cpu_seconds_per_image(checkpoint.net, repeats=15, as_trained=True)
            )
            if args.flip_average:
                seconds = cpu_seconds_per_image(checkpoint.net, repeats=15, flip_average=True)
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
            "flip_average_target_met": seconds <= SECONDS_PER_IMAGE_TARGET,
        }

    figures = {
        "checkpoints": {
            c.label: {
                "path": str(c.path),
                "digest": c.digest,
                "network": c.net.config.to_json(),
                "parameters": parameter_count(c.net),
                "seconds_per_512x288_image_rounds": times[c.label],
                "seconds_per_512x288_image": round(median[c.label], 4),
                "ratio_to_baseline": round(median[c.label] / baseline, 2),
                "target_met": median[c.label] <= SECONDS_PER_IMAGE_TARGET,
                "as_trained_seconds_rounds": trained[c.label],
                "as_trained_seconds": round(median_trained[c.label], 4),
                "ratio_to_as_trained": round(median[c.label] / median_trained[c.label], 2),
                **with_flip(c.label),
            }
            for c in checkpoints
        },
        "baseline": checkpoints[0].label,
        "target_s": SECONDS_PER_IMAGE_TARGET,
        "command": "python bench/segment_speed.py " + " ".join(sys.argv[1:]),
        "machine": {"python": platform.python_version(), "time": time.strftime("%Y-%m-%d %H:%M")},
    }
    print(json.dumps(figures["checkpoints"], indent=1))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(figures, indent=1) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
