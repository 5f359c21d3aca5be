"""Element-mask proposer (network geometry) against the rule-based proposer on sites the network never saw.

The element-mask network (`models.vma.element_masks`: a BEV segmentation U-Net over the one-hot semantic + RGB
rasters, its class masks traced into polylines) is scored beside the rule-based proposer, in one run, on:
1. BEV-only held-out generator sites (seeds 2000-2004; the same as `bench/vma.py`), clean and with the same
   reconstruction-like damage `bench/vma.py` applies (`models.vma.degrade`, default strengths, seeded by site);
2. reconstructed rasters: the surface stage's BEV of full synthetic sites (`--recon-site`, default: the
   default site and the randomised site 9001, each with `cama run` done), against the true vectors inside the
   reconstructed extent and cut to the observed cells; both proposers run there as `cama run` runs them
   (the rules' boundaries follow the road's edge; the network's snap to it where it is seen).
Figures per proposer and condition: Chamfer-AP at 0.5 / 1.0 / 1.5 m per class and mean (30 m tiles), the
confidence bins, and the scripted annotator's speed-up over drawing (`app.review_effort.review_time`). Every
site is first checked never to have been seen by the checkpoint (`models.vma.checkpoint.ensure_unseen`: an
error, not a skip).

Usage: .venv/bin/python bench/vma_masks.py [--checkpoint models/vma/element_masks/checkpoints]
       [--seeds 2000-2004] [--recon-site data/synthetic/default ...] [--threads 2] [--out bench/results/vma_masks.json]
"""

import argparse
import platform
import sys
import time
from pathlib import Path
from typing import Any

import torch
from rich.console import Console

from app.review_effort.review_time import review_time
from cama_pipeline.io import atomic_write_json
from models.vma.bev_sites import ensure_bev_sites
from models.vma.checkpoint import ensure_unseen
from models.vma.commands import seed_range
from models.vma.element_masks.checkpoint import load_mask_checkpoint
from models.vma.element_masks.propose import predict_site_masks
from models.vma.evaluate import evaluate_proposer
from models.vma.rasters import SiteRasters
from models.vma.rule_based import RuleConfig, propose_rule_based
from models.vma.validation import reconstruction_of
from models.vma.vectors import Vector

# the shared conditions: `bench` is a package at the repository root
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from bench.vma_measures import on_damaged, reconstructed_figures  # noqa: E402

RESULTS = Path(__file__).parent / "results"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--checkpoint", type=Path, default=Path("models/vma/element_masks/checkpoints"))
    parser.add_argument("--seeds", default="2000-2004", help="held-out BEV site seeds ('A-B')")
    parser.add_argument("--site-root", type=Path, default=Path("data/vma/heldout"))
    parser.add_argument(
        "--recon-site",
        type=Path,
        action="append",
        help="synthetic site with `cama run` done (repeatable; default: data/synthetic/default and random-9001)",
    )
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--out", type=Path, default=RESULTS / "vma_masks.json")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    console = Console()
    held_out = ensure_bev_sites(seed_range(args.seeds), args.site_root)
    recon = args.recon_site or [Path("data/synthetic/default"), Path("data/synthetic/random-9001")]
    checkpoint = load_mask_checkpoint(args.checkpoint)
    for site in [*held_out, *recon]:  # SeenSiteError when the network trained on a site scored here
        ensure_unseen(checkpoint, site)
    started = time.perf_counter()
    reconstructions = [reconstruction_of(site) for site in recon]

    def network(rasters: SiteRasters) -> list[Vector]:
        return predict_site_masks(checkpoint.model, rasters)

    def rule_on_reconstruction(rasters: SiteRasters) -> list[Vector]:
        return propose_rule_based(rasters, RuleConfig(boundary_source="road_edge"))

    results: dict[str, dict[str, Any]] = {"clean": {}, "degraded": {}, "reconstructed": {}}
    for name, propose, recon_propose in (
        ("rule_based", propose_rule_based, rule_on_reconstruction),
        ("element_masks", network, network),
    ):
        console.print(f"evaluating {name} ...")
        for condition, run in (("clean", propose), ("degraded", on_damaged(propose))):
            results[condition][name] = {
                **evaluate_proposer(run, held_out),
                "annotator": review_time(run, held_out),
            }
        results["reconstructed"][name] = reconstructed_figures(recon_propose, reconstructions)
    margins = {
        condition: _margin(per, "observed_truth" if condition == "reconstructed" else None)
        for condition, per in results.items()
    }
    report = {
        "command": f"python bench/vma_masks.py --checkpoint {args.checkpoint} --seeds {args.seeds} "
        f"--site-root {args.site_root} "
        + " ".join(f"--recon-site {s}" for s in recon)
        + f" --threads {args.threads} --out {args.out}",
        "held_out_seeds": seed_range(args.seeds),
        "checkpoint": {
            "version": checkpoint.path.name,
            "data": checkpoint.meta.get("data"),
            "model_config": checkpoint.meta.get("model_config"),
            "train_metrics": checkpoint.meta.get("metrics"),
        },
        "results": results,
        # where each reconstruction's rasters sit against the world: its truth is carried by this
        "reconstruction_frames": {
            str(site.site): site.frame.as_dict() if site.frame else None for site in reconstructions
        },
        "map_margin_over_rule_based": margins,
        "machine": {"cpu_threads": args.threads, "platform": platform.platform(), "device": "cpu"},
        "seconds": round(time.perf_counter() - started, 1),
    }
    atomic_write_json(args.out, report, indent=1)
    for condition, per in results.items():
        for name, result in per.items():
            scored = result["observed_truth"] if condition == "reconstructed" else result
            classes = ", ".join(f"{c} {v:.3f}" for c, v in scored["class_ap"].items())
            console.print(
                f"[bold]{condition} {name}[/bold]: mAP {scored['mean_ap']:.3f} ({classes}); "
                f"annotator {result['annotator']['speed_up']:.2f}x"
            )
            for site, figures in scored.get("per_site", {}).items():
                console.print(f"    {site}: mAP {figures['mean_ap']:.3f}")
    console.print(f"margins over rule-based: {margins}; written to {args.out}")


def _margin(per: dict[str, Any], truth: str | None) -> float:
    """The network's mAP minus the rule-based proposer's."""

    def score(name: str) -> float:
        return float((per[name][truth] if truth else per[name])["mean_ap"])

    return round(score("element_masks") - score("rule_based"), 4)


if __name__ == "__main__":
    main()
