"""Acceptance benchmark of the SRE evaluation: the true 3D map against the flawed 2D baseline map.

(a) the ground-truth 3D vector map projected with the true poses: error from the masks alone;
(b) the baseline 2D map (no elevation, rule-based and missing dividers, small offset) projected with the
    coarse logged ego poses and the flat-ground assumption (z = ego height), as the paper's nuScenes row.
Two more rows separate the two causes: the true map with coarse poses, the baseline map with true poses.

Each row records `sre_ref_px`, the SRE at 960x540 (the paper's and CAMA's scale; the figure README quotes), beside
`sre_px` in the images' own pixels (512 wide on the synthetic sites), precision, recall and F1.

Usage: .venv/bin/python bench/sre_baseline.py [--site data/synthetic/default] [--boundaries]
Prints the figures (SRE at 960x540 first) and writes them and the command to bench/results/sre_baseline.json.
"""

import argparse
import json
import platform
import sys
import time
from pathlib import Path

from rich.console import Console

from cama_pipeline.data import load_dataset
from cama_pipeline.evaluate import SreConfig, SreSummary, evaluate_sre, load_true_poses, load_vector_map
from cama_pipeline.evaluate.command import report_table
from cama_pipeline.semantics import Semantic

RESULTS = Path(__file__).parent / "results"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--site", type=Path, default=Path("data/synthetic/default"))
    parser.add_argument("--boundaries", action="store_true", help="also match boundaries with curb instances")
    parser.add_argument("--out", type=Path, default=RESULTS / "sre_baseline.json")
    args = parser.parse_args()
    pairs = [("divider", int(Semantic.LANE_MARKING))]
    if args.boundaries:
        pairs.append(("boundary", int(Semantic.CURB)))
    config = SreConfig(class_pairs=tuple(pairs))
    dataset = load_dataset(args.site / "nuscenes")
    truth = args.site / "ground_truth"
    true_poses = load_true_poses(truth / "poses.json")
    gt_map = load_vector_map(truth / "vector_map.json")
    baseline = load_vector_map(truth / "baseline_map.json")
    runs = {
        "a_gt3d_true_poses": (gt_map, true_poses),
        "b_baseline2d_coarse_poses": (baseline, None),
        "gt3d_coarse_poses": (gt_map, None),
        "baseline2d_true_poses": (baseline, true_poses),
    }
    figures: dict[str, object] = {"site": str(args.site), "class_pairs": pairs}
    for name, (elements, poses) in runs.items():
        started = time.perf_counter()
        report = evaluate_sre(dataset, elements, config, true_poses=poses, show_progress=True)
        seconds = time.perf_counter() - started
        Console().print(report_table(report, name))
        figures[name] = {
            **report.to_json(with_images=False),
            "seconds": round(seconds, 1),
        }
        del figures[name]["config"]
        print(headline(name, report.overall))
    figures["config"] = report.to_json(with_images=False)["config"]
    figures["command"] = "python bench/sre_baseline.py " + " ".join(sys.argv[1:])
    figures["machine"] = {"python": platform.python_version()}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(figures, indent=2) + "\n")
    print(f"written {args.out}")


def headline(name: str, summary: SreSummary) -> str:
    """One row's figures, SRE at 960x540 (`sre_ref_px`) first, the images' own pixels after it."""
    return (
        f"{name}: SRE {_fmt(summary.sre_ref_px)} px at 960x540 (sre_ref_px; {_fmt(summary.sre_px)} px at the"
        f" images' own width), precision {_fmt(summary.precision)}, recall {_fmt(summary.recall)},"
        f" F1 {_fmt(summary.f1)}, images {summary.images}"
    )


def _fmt(value: object) -> str:
    """Three decimals for floats."""
    return f"{value:.3f}" if isinstance(value, float) else str(value)


if __name__ == "__main__":
    main()
