"""The surface's SfM gate: which SfM road points join the elevation fit, on sites whose road grade changes or not.

The elevation MLP is fitted first to the strip under the keyframes; beyond the strip its curvature prior continues
it like a plane. SfM road points within `sfm_gate_m` of that fit then join it (`cama_pipeline.surface.fit`), and
with `sfm_gate_rounds` > 1 they are gated again against each new fit while the inliers grow. Where the grade
changes past the ends of the drives (a hill that flattens), the points there lie further than a tight gate from the
plane and never correct it. Each variant below runs the surface stage with the site's SfM poses, as the product
does (`bench/surface.py`'s `run_source`: a fresh workspace sharing the site's sites, SfM and masks), all in one run
per site, and is scored as `bench/surface.py` scores a run: the road's elevation RMSE (and by distance from the
trajectory), the class IoU against the truth in the world's frame and in the reconstruction's own, PSNR, seconds.

Usage: .venv/bin/python bench/surface_gate.py --site SITE [--site SITE ...] [--variant NAME=GATE_M,ROUNDS ...]
       [--threads 2] [--out bench/results/surface_gate.json]
The first variant is the baseline the others are compared with (default: the shipped `SurfaceConfig`'s gate).
"""

import argparse
import platform
import shutil
import sys
import tempfile
from dataclasses import replace
from pathlib import Path
from typing import Any

import torch

from cama_pipeline.io import atomic_write_json
from cama_pipeline.surface import SurfaceConfig

RESULTS = Path(__file__).parent / "results"
DEFAULT_VARIANTS = (
    "gate 0.1 m=0.1,1",
    "gate 0.5 m=0.5,1",
    "gate 0.5 m, 4 rounds=0.5,4",
    "gate 1 m, 4 rounds=1.0,4",
)


def parse_variant(text: str) -> tuple[str, float, int]:
    """`NAME=GATE_M,ROUNDS` -> (name, gate in metres, rounds); SystemExit naming the text when malformed."""
    name, _, values = text.rpartition("=")
    try:
        gate_text, rounds_text = values.split(",")
        gate_m, rounds = float(gate_text), int(rounds_text)
    except ValueError:
        raise SystemExit(f"--variant {text!r}: expected NAME=GATE_M,ROUNDS, e.g. 'wide=0.5,4'") from None
    if not name or gate_m <= 0 or rounds < 1:
        raise SystemExit(f"--variant {text!r}: a name, a gate > 0 and rounds >= 1 are needed")
    return name, gate_m, rounds


def figures(run: dict[str, Any]) -> dict[str, Any]:
    """What the comparison reads of a `run_source` result."""
    return {
        "elevation_rmse_cm": run["elevation_rmse_m"] * 100,
        "elevation_rmse_cm_by_distance_m": {
            span: value * 100 for span, value in run["elevation_rmse_m_by_distance_from_trajectory_m"].items()
        },
        "iou": run["iou"],
        "iou_in_reconstruction_frame": run["in_reconstruction_frame"]["iou"],
        "psnr_db": run["psnr_db"],
        "sfm_points_kept": run["points"].get("sfm_kept"),
        "seconds": run["seconds"]["total"],
    }


def main() -> None:
    from surface import (
        run_source,
    )  # bench/surface.py, on sys.path when this runs as a script (tests import the rest)

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--site", type=Path, action="append", required=True, help="a site with its SfM run")
    parser.add_argument("--variant", action="append", default=None, help="NAME=GATE_M,ROUNDS (repeatable)")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--out", type=Path, default=RESULTS / "surface_gate.json")
    args = parser.parse_args()
    variants = [parse_variant(text) for text in (args.variant or DEFAULT_VARIANTS)]
    base = SurfaceConfig(torch_threads=args.threads)
    sites: dict[str, Any] = {}
    for site in args.site:
        runs: dict[str, Any] = {}
        for name, gate_m, rounds in variants:
            scratch = Path(tempfile.mkdtemp(prefix="bench-surface-gate-"))
            try:
                config = replace(base, sfm_gate_m=gate_m, sfm_gate_rounds=rounds)
                runs[name] = {
                    "sfm_gate_m": gate_m,
                    "sfm_gate_rounds": rounds,
                    **figures(run_source(site, "sfm", config, scratch)),
                }
            finally:
                shutil.rmtree(scratch, ignore_errors=True)
            own = runs[name]["iou_in_reconstruction_frame"]
            print(
                f"{site.name} {name}: elevation {runs[name]['elevation_rmse_cm']:.2f} cm, own frame IoU "
                + " / ".join(f"{own[c]:.3f}" for c in ("road", "curb", "lane_marking", "crosswalk"))
                + f", {runs[name]['seconds']:.0f} s",
                flush=True,
            )
        baseline = runs[variants[0][0]]
        sites[str(site)] = {
            "runs": runs,
            "against_baseline": {
                name: {
                    "elevation_rmse_cm": run["elevation_rmse_cm"] - baseline["elevation_rmse_cm"],
                    "iou_in_reconstruction_frame": {
                        c: v - baseline["iou_in_reconstruction_frame"][c]
                        for c, v in run["iou_in_reconstruction_frame"].items()
                    },
                    "seconds_ratio": run["seconds"] / max(baseline["seconds"], 1e-9),
                }
                for name, run in runs.items()
            },
        }
    results = {
        "command": " ".join([sys.executable.split("/")[-1], *sys.argv]),
        "poses": "sfm",
        "machine": {"platform": platform.platform(), "torch": torch.__version__, "threads": args.threads},
        "sites": sites,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_json(args.out, results, indent=1)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
