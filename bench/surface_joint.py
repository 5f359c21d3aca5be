"""The joint optimisation by differentiable rendering (`surface.joint`) against the observation vote alone.

For each site and pose source, `cama surface` runs into temporary workspaces (`bench/surface.py`'s `run_source`,
which shares the site's `sites/` and `sfm/`): once with today's defaults (the vote, `joint.epochs` 0) and once per
variant with `--epochs` passes of the joint optimisation: `defaults` (the other `JointConfig` settings at their
defaults) and each `--variant NAME=JSON` (`JointConfig` fields over the defaults). Every run is scored against the
site's ground truth as `bench/surface.py` scores it (elevation RMSE of the road cells and of road and curb with the
kerb steps, class IoUs, PSNR against the true albedo) and each variant's difference from the vote is recorded with
each phase's seconds.

Usage: .venv/bin/python bench/surface_joint.py [--site data/synthetic/default ...] [--sources ground_truth,sfm]
       [--epochs 2] [--variant 'revote={"vote_after": true}' ...] [--out bench/results/surface_joint.json]
"""

import argparse
import json
import logging
import platform
import shutil
import sys
import tempfile
from dataclasses import replace
from pathlib import Path
from typing import Any

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from bench.surface import IOU_CLASSES, run_source  # noqa: E402
from cama_pipeline.io import atomic_write_json  # noqa: E402
from cama_pipeline.surface import SurfaceConfig  # noqa: E402

RESULTS = Path(__file__).parent / "results"


def summary(row: dict[str, Any]) -> dict[str, Any]:
    """The figures the comparison reads from one `run_source` row."""
    return {
        "elevation_rmse_m": row["elevation_rmse_m"],
        "elevation_rmse_m_road_and_curb": row["kerb"]["elevation_rmse_m_road_and_curb"],
        "elevation_rmse_m_by_distance_from_trajectory_m": row[
            "elevation_rmse_m_by_distance_from_trajectory_m"
        ],
        "iou": row["iou"],
        "curb_confusion": row["curb_confusion"],
        "psnr_db": row["psnr_db"],
        "seconds": row["seconds"],
    }


def difference(joint: dict[str, Any], vote: dict[str, Any]) -> dict[str, Any]:
    """Joint minus vote: elevation RMSE in cm, IoU, PSNR in dB; and the time ratio."""
    return {
        "elevation_rmse_cm": 100 * (joint["elevation_rmse_m"] - vote["elevation_rmse_m"]),
        "elevation_rmse_road_and_curb_cm": 100
        * (joint["elevation_rmse_m_road_and_curb"] - vote["elevation_rmse_m_road_and_curb"]),
        "iou": {name: joint["iou"][name] - vote["iou"][name] for name in IOU_CLASSES},
        "psnr_db": joint["psnr_db"] - vote["psnr_db"],
        "seconds_ratio": joint["seconds"]["total"] / max(vote["seconds"]["total"], 1e-9),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--site", type=Path, action="append", help="synthetic site folder (repeatable)")
    parser.add_argument("--sources", default="ground_truth,sfm", help="pose sources")
    parser.add_argument("--epochs", type=int, default=2, help="passes of the joint optimisation")
    parser.add_argument(
        "--variant",
        action="append",
        default=[],
        help='NAME={"field": value, ...}: JointConfig fields of a variant',
    )
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--out", type=Path, default=RESULTS / "surface_joint.json", help="figures JSON")
    args = parser.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    sites = args.site or [Path("data/synthetic/default")]
    vote = SurfaceConfig(torch_threads=args.threads)
    variants = {"defaults": replace(vote.joint, epochs=args.epochs)}
    for text in args.variant:
        name, _, fields = text.partition("=")
        variants[name] = replace(variants["defaults"], **json.loads(fields))
    rows = []
    scratch = Path(tempfile.mkdtemp(prefix="bench-surface-joint-"))
    try:
        for site in sites:
            for poses in args.sources.split(","):
                voted = summary(run_source(site, poses, vote, scratch))
                row: dict[str, Any] = {"site": str(site), "poses": poses, "vote": voted, "variants": {}}
                for name, joint in variants.items():
                    rendered = summary(run_source(site, poses, replace(vote, joint=joint), scratch))
                    change = difference(rendered, voted)
                    row["variants"][name] = {"figures": rendered, "minus_vote": change}
                    print(
                        f"{site} {poses} {name}: RMSE {100 * voted['elevation_rmse_m']:.2f} -> "
                        f"{100 * rendered['elevation_rmse_m']:.2f} cm, "
                        + ", ".join(
                            f"{cls} {voted['iou'][cls]:.3f} -> {rendered['iou'][cls]:.3f}"
                            for cls in IOU_CLASSES
                        )
                        + f", PSNR {voted['psnr_db']:.2f} -> {rendered['psnr_db']:.2f} dB, "
                        f"time x{change['seconds_ratio']:.2f}"
                    )
                rows.append(row)
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    results = {
        "command": " ".join([sys.executable.split("/")[-1], *sys.argv]),
        "variants": {
            name: {**vars(joint), "search_m": list(joint.search_m)} for name, joint in variants.items()
        },
        "threads": args.threads,
        "machine": {
            "platform": platform.platform(),
            "torch": torch.__version__,
            "cuda": torch.cuda.is_available(),
        },
        "runs": rows,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_json(args.out, results, indent=1)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
