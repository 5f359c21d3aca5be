"""Acceptance benchmark of the VMA proposers on held-out synthetic sites that training never saw.

Held-out sites are BEV-only generator sites of seeds 2000-2004 (layouts drawn from the seed, each its own
location; the shipped v0003 trained on seeds 1000-1011 and was gated on 3000-3002; every checkpoint scored is first
checked never to have trained on a held-out site, `models.vma.checkpoint.ensure_unseen`). Proposers: the
rule-based one, the promoted learned checkpoint (`learned`: the anchored hybrid whose instance queries start
from rule-based candidates, output as the candidates rescored by the model), the same network's own refined
points (`learned_refined`) and, for comparison, the free-query MapTR checkpoint (`learned_free`, v0001). For each:
Chamfer-AP at 0.5 / 1.0 / 1.5 m per class and mean (MapTR protocol, 30 m evaluation tiles), precision per
confidence bin (does confidence rank errors?), and inference seconds per km² of site on this machine's CPU
threads (torch limited to --threads). Two input conditions: the generator's clean rasters, and the same
rasters with reconstruction-like damage (`models.vma.degrade`: missed marking pieces, edge jitter, speckle,
colour noise; seeded per site) that all proposers receive alike. The calibrated pre-accept threshold of each
proposer on these sites is reported too (`models.vma.loop`).

Usage: .venv/bin/python bench/vma.py [--checkpoint models/vma/checkpoints]
       [--free-checkpoint models/vma/checkpoints/v0001 | ''] [--seeds 2000-2004] [--threads 2]
Prints the figures and writes them to bench/results/vma.json.
"""

import argparse
import json
import platform
import time
from collections.abc import Callable
from pathlib import Path

import torch
from rich.console import Console

from models.vma.bev_sites import ensure_bev_sites
from models.vma.checkpoint import ensure_unseen, load_checkpoint
from models.vma.commands import seed_range
from models.vma.degrade import DegradeConfig, degrade_rasters
from models.vma.evaluate import evaluate_proposer
from models.vma.infer import InferenceConfig, predict_site
from models.vma.model import VmaNet
from models.vma.rasters import SiteRasters
from models.vma.rule_based import propose_rule_based
from models.vma.vectors import Vector

RESULTS = Path(__file__).parent / "results"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--checkpoint", type=Path, default=Path("models/vma/checkpoints"))
    parser.add_argument(
        "--free-checkpoint",
        default="models/vma/checkpoints/v0001",
        help="free-query MapTR checkpoint to compare ('' to skip)",
    )
    parser.add_argument("--seeds", default="2000-2004", help="held-out site seeds ('A-B')")
    parser.add_argument("--site-root", type=Path, default=Path("data/vma/heldout"))
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--out", type=Path, default=RESULTS / "vma.json")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    console = Console()
    sites = ensure_bev_sites(seed_range(args.seeds), args.site_root)
    checkpoint = load_checkpoint(args.checkpoint)
    free = load_checkpoint(Path(args.free_checkpoint)) if args.free_checkpoint else None
    for site in sites:  # SeenSiteError when a checkpoint trained on a held-out site
        for model in (checkpoint, free):
            if model is not None:
                ensure_unseen(model, site)
    started = time.perf_counter()

    proposers: dict[str, Callable[[SiteRasters], list[Vector]]] = {
        "rule_based": propose_rule_based,
        "learned": _learned(checkpoint.model, InferenceConfig()),
    }
    if checkpoint.config.anchored:  # the same network with its own refined points instead of the candidates'
        proposers["learned_refined"] = _learned(checkpoint.model, InferenceConfig(anchored_output="refined"))
    if free is not None:
        proposers["learned_free"] = _learned(free.model, InferenceConfig())
    results: dict[str, dict] = {"clean": {}, "degraded": {}}
    for name, propose in proposers.items():
        console.print(f"evaluating {name} ...")
        results["clean"][name] = evaluate_proposer(propose, sites)
        results["degraded"][name] = evaluate_proposer(_on_degraded(propose), sites)
    report = {
        "command": "python bench/vma.py "
        + f"--checkpoint {args.checkpoint} --free-checkpoint '{args.free_checkpoint}' "
        + f"--seeds {args.seeds} --threads {args.threads}",
        "held_out_seeds": seed_range(args.seeds),
        "checkpoint": {
            "version": checkpoint.path.name,
            "data": checkpoint.meta.get("data"),
            "model_config": checkpoint.meta.get("model_config"),
            "train_metrics": {
                k: v for k, v in (checkpoint.meta.get("metrics") or {}).items() if k != "validation"
            },
        },
        "results": results,
        "learned_beats_rule_based": {
            condition: _beats(per["learned"]["mean_ap"], per["rule_based"]["mean_ap"])
            for condition, per in results.items()
        },
        "machine": {"cpu_threads": args.threads, "platform": platform.platform(), "device": "cpu"},
        "seconds": round(time.perf_counter() - started, 1),
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(report, indent=1) + "\n", encoding="utf-8")
    for condition, per in results.items():
        for name, result in per.items():
            classes = ", ".join(f"{c} {_fmt(v)}" for c, v in result["class_ap"].items())
            console.print(
                f"[bold]{condition} {name}[/bold]: mAP {_fmt(result['mean_ap'])} ({classes}); "
                f"{result['seconds_per_km2']:.1f} s/km² (incl. damage on 'degraded'); "
                f"pre-accept threshold {_fmt(result['preaccept_threshold'])}"
            )
            bins = "  ".join(
                f"[{b['low']:.2f},{b['high']:.2f}) n={b['count']} P={_fmt(b['precision'])}"
                for b in result["confidence_bins"]
            )
            console.print(f"  precision per confidence bin: {bins}")
    console.print(f"written to {args.out}")


def _learned(model: VmaNet, config: InferenceConfig) -> Callable[[SiteRasters], list[Vector]]:
    def run(rasters: SiteRasters) -> list[Vector]:
        return predict_site(model, rasters, config, show_progress=False)

    return run


def _on_degraded(
    propose: Callable[[SiteRasters], list[Vector]],
) -> Callable[[SiteRasters], list[Vector]]:
    """The proposer run on the site's rasters with reconstruction-like damage, seeded by the site's name."""

    def run(rasters: SiteRasters) -> list[Vector]:
        return propose(degrade_rasters(rasters, DegradeConfig(seed=sum(rasters.name.encode()))))

    return run


def _beats(learned_map: float | None, rule_map: float | None) -> bool:
    return learned_map is not None and rule_map is not None and learned_map > rule_map


def _fmt(value: float | None) -> str:
    return "-" if value is None else f"{value:.2f}"


if __name__ == "__main__":
    main()
