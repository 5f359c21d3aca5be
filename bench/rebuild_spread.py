"""How much a held-out figure moves between reconstructions of one data set: noise a candidate must beat.

Each `--site` (a synthetic site: data set, ground truth and manifest) is reconstructed again in a scratch folder
by the whole path (`cama_studio.pipeline.run`, defaults) once per `--seeds` value of the two-view verification's
RANSAC seed (`FeaturesConfig.ransac_seed`), the only change; the promoted element-mask network of `--checkpoint`
then proposes on each reconstruction with the product's settings and is scored as the loop and `bench/vma_masks.py`
score it (`reconstructed_figures`: Chamfer mAP against the truth the cameras observed, and the scripted
annotator's correction time and speed-up over drawing). Per site: each seed's figures and the spread (max - min);
over all sites: the spread of the total correction time, against the per-site differences the retrain gate
weighs (README, "A confident saving"). A checkpoint is refused on a site it saw (`ensure_unseen`).

Usage: .venv/bin/python bench/rebuild_spread.py --site data/synthetic/random-9013 [--site ...] [--seeds 0-2]
       [--checkpoint models/vma/element_masks/checkpoints] [--threads 2] [--out bench/results/rebuild_spread.json]
"""

import argparse
import dataclasses
import platform
import shutil
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import torch

from cama_pipeline.io import atomic_write_json
from cama_studio.config import PipelineConfig
from cama_studio.pipeline import run as run_pipeline
from models.vma.commands import seed_range
from models.vma.element_masks.propose import product_proposer
from models.vma.rasters import SiteRasters
from models.vma.validation import reconstruction_of
from models.vma.vectors import Vector

# the shared conditions: `bench` is a package at the repository root
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from bench.vma_measures import reconstructed_figures, unseen_mask_checkpoint  # noqa: E402

RESULTS = Path(__file__).parent / "results"
SITE_PARTS = ("nuscenes", "ground_truth", "manifest.json")
"""What a synthetic site holds besides its workspace: copied, so each rebuild starts from the data alone."""


def copy_site(site: Path, into: Path) -> Path:
    """`site`'s data set, truth and manifest copied to `into` (no workspace); ValueError naming a missing part."""
    missing = [site / part for part in SITE_PARTS if not (site / part).exists()]
    if missing:
        raise ValueError(f"{site}: not a synthetic site, {missing[0]} is missing")
    for part in SITE_PARTS:
        source, target = site / part, into / part
        if source.is_dir():
            shutil.copytree(source, target)
        else:
            into.mkdir(parents=True, exist_ok=True)
            shutil.copy2(source, target)
    return into


def rebuilt_figures(
    site: Path, seed: int, scratch: Path, propose: Callable[[SiteRasters], list[Vector]]
) -> dict[str, Any]:
    """The whole path on a fresh copy of `site` with verification seed `seed`, and the proposer's figures on it."""
    copy = copy_site(site, scratch / f"{site.name}-seed-{seed}")
    config = PipelineConfig()
    config = dataclasses.replace(config, features=dataclasses.replace(config.features, ransac_seed=seed))
    started = time.perf_counter()
    run_pipeline(copy / "nuscenes", config=config)
    build_s = time.perf_counter() - started
    figures = reconstructed_figures(propose, [reconstruction_of(copy)])
    return {
        "seed": seed,
        "build_seconds": round(build_s, 1),
        "mean_ap": figures["observed_truth"]["mean_ap"],
        "correction_s": figures["annotator"]["correction_s"],
        "drawing_s": figures["annotator"]["drawing_s"],
        "speed_up": figures["annotator"]["speed_up"],
    }


def spread(values: list[float]) -> float:
    """Max - min."""
    return max(values) - min(values)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--site", type=Path, action="append", required=True, help="synthetic site (repeatable)"
    )
    parser.add_argument("--seeds", default="0-2", help="verification RANSAC seeds ('A-B')")
    parser.add_argument("--checkpoint", type=Path, default=Path("models/vma/element_masks/checkpoints"))
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--out", type=Path, default=RESULTS / "rebuild_spread.json")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    checkpoint = unseen_mask_checkpoint(args.checkpoint, args.site)
    propose = product_proposer(checkpoint.model)
    seeds = seed_range(args.seeds)
    if len(seeds) < 2:
        raise SystemExit(f"--seeds: a spread needs two seeds at least, got {args.seeds!r}")
    started = time.perf_counter()
    sites: dict[str, Any] = {}
    scratch = Path(tempfile.mkdtemp(prefix="bench-rebuild-spread-"))
    try:
        jobs = [(site, seed) for site in args.site for seed in seeds]
        for k, (site, seed) in enumerate(jobs, start=1):
            entry = sites.setdefault(str(site), {"builds": []})
            entry["builds"].append(rebuilt_figures(site, seed, scratch, propose))
            build = entry["builds"][-1]
            print(
                f"[{k}/{len(jobs)}] {site} seed {seed}: {build['correction_s']:.1f} s of correction, "
                f"{build['speed_up']:.2f}x, mAP {build['mean_ap']:.3f} ({time.perf_counter() - started:.0f} s)",
                flush=True,
            )
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    for entry in sites.values():
        builds = entry["builds"]
        entry["correction_s_spread"] = spread([b["correction_s"] for b in builds])
        entry["speed_up_spread"] = spread([b["speed_up"] for b in builds])
        entry["mean_ap_spread"] = spread([b["mean_ap"] for b in builds])
    totals = [sum(entry["builds"][k]["correction_s"] for entry in sites.values()) for k in range(len(seeds))]
    report = {
        "command": "python bench/rebuild_spread.py "
        + "".join(f"--site {site} " for site in args.site)
        + f"--seeds {args.seeds} --checkpoint {args.checkpoint} --threads {args.threads}",
        "checkpoint": str(checkpoint.path),
        "sites": sites,
        "total_correction_s": totals,
        "total_correction_s_spread": spread(totals),
        "machine": {"cpu_threads": args.threads, "platform": platform.platform(), "device": "cpu"},
        "seconds": round(time.perf_counter() - started, 1),
    }
    atomic_write_json(args.out, report)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
