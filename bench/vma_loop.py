"""The human-in-the-loop rounds measured (issue 26.4): propose, let the simulated annotator correct, retrain, gate.

Round 0 is either the promoted model of `--checkpoint` (the shipped MapTR-style v0003, or an element-mask
registry, `models/vma/element_masks/checkpoints`, whose network draws its own geometry), copied into a scratch
registry, or, with `--bootstrap-seeds A-B`, an element-mask network trained from scratch here on the generator's
truth of those few BEV sites (`--bootstrap-steps` batches): a team's first model, before any correction. Round k
(1..N) takes a new BEV site (seed `--new-seeds`, one per round, never seen by any model here): the current model
proposes on it (`--propose-on damaged`: on its rasters with reconstruction-like damage, as the product proposes on
reconstructions), or, with `--new-recon-site`, a synthetic site's reconstruction (`cama run` done), proposed on as
it is with the product's settings and corrected against the truth its cameras observed; the scripted annotator
(`app.review_effort`, in-memory queue) accepts, fixes or rejects each proposal against the truth and draws what is
missing; its verdicts become corrections (accepted / fixed / drawn as
labels, rejected as negatives). The retrain then fine-tunes on the corrections of every round so far (as the
lead's retrain job learns from every site in the database; `--corrections latest`: this round's only), behind
both gates (validation mAP and the annotator's correction time on the validation sites: BEV sites `--val-seeds`
and the reconstructions of `--gate-recon-site`, as a server's CAMA_VMA_VALIDATION_RECONSTRUCTED gates; a saving
counts when it holds in `--time-confidence` of bootstrap resamples of those sites, `models.vma.gate`); the
element-mask network rehearses `--replay-sites` of its own generator training sites and `--replay-reconstructions`
of the reconstructions it trained on in `--replay-share` of its crops; `--retrain-from first` trains round 0's
element-mask network on every correction so far for `--steps` per corrected site instead of fine-tuning the promoted
one (so one round's drift does not carry into the next). After
every round the promoted model is measured on held-out sites never proposed on, corrected or validated on: BEV
sites `--heldout-seeds` (Chamfer mAP clean and damaged, `models.vma.degrade`; the annotator's speed-up over
drawing on clean rasters) and, for the element-mask network, the surface stage's reconstructed rasters of full
synthetic sites (`--recon-site`, as `bench/vma_masks.py` scores them). The rule-based proposer is measured beside
it once. A checkpoint is refused on a held-out or validation site it saw (`ensure_unseen`).

Usage: .venv/bin/python bench/vma_loop.py [--checkpoint REGISTRY | --bootstrap-seeds A-B] [--rounds 3]
       [--steps 300] [--new-seeds A-B | --new-recon-site SITE ...] [--val-seeds A-B] [--gate-recon-site SITE]
       [--recon-site SITE] [--replay-sites 4] [--replay-reconstructions 0] [--replay-share 0] [--threads 2]
       [--time-confidence 0.9] [--map-tolerance 0] [--retrain-from promoted|first]
       [--out bench/results/vma_loop.json]
       [--plot-only] [--keep-registry DIR]
Writes bench/results/vma_loop.json and the plot bench/results/vma_loop/rounds.png (`--out X.json`: X/rounds.png;
`--plot-only`: the plot from the JSON); `--keep-registry DIR` keeps the loop's checkpoints (for shipping one).
"""

import argparse
import json
import platform
import shutil
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import matplotlib
import numpy as np
import torch

from annotations import Georeference
from app.review_effort.costs import ActionCosts
from app.review_effort.plan import SimulationConfig
from app.review_effort.review_time import MIN_CONFIDENCE, review_queue, review_time
from app.review_effort.session import work_queue
from app.review_effort.truth import observed_true_polylines, true_polylines
from models.vma.bev_sites import ensure_bev_sites
from models.vma.checkpoint import checkpoint_kind, current_version, ensure_unseen, load_checkpoint, promote
from models.vma.commands import seed_range
from models.vma.config import TrainConfig
from models.vma.element_masks.checkpoint import KIND as MASK_KIND
from models.vma.element_masks.checkpoint import load_mask_checkpoint
from models.vma.element_masks.config import MaskModelConfig, MaskTrainConfig
from models.vma.element_masks.propose import product_proposer
from models.vma.element_masks.retrain import MaskRetrainConfig, retrain_masks_from_corrections
from models.vma.element_masks.train import train_masks
from models.vma.evaluate import evaluate_proposer
from models.vma.gate import TIME_CONFIDENCE, review_saving_confidence
from models.vma.infer import InferenceConfig
from models.vma.rasters import SiteRasters, load_site_rasters
from models.vma.retrain import (
    Corrections,
    RetrainConfig,
    RetrainResult,
    model_proposer,
    retrain_from_corrections,
)
from models.vma.rule_based import RuleConfig, propose_rule_based
from models.vma.vectors import Vector, proposals_as_annotations, simple_geometry

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

# the shared conditions: `bench` is a package at the repository root
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from bench.vma_measures import on_damaged, reconstructed_figures  # noqa: E402
from models.vma.validation import (  # noqa: E402
    ValidationEntry,
    ValidationSite,
    as_validation_site,
    reconstruction_of,
    truth_folder,
)

RESULTS = Path(__file__).parent / "results"
Proposer = Callable[[SiteRasters], list[Vector]]


def corrections_of(entry: ValidationEntry, propose: Proposer) -> tuple[Corrections, dict[str, int]]:
    """The scripted annotator's review of `propose`'s output on a new site, as retraining's corrections: on a BEV
    site's rasters against its truth, or on a reconstruction's against the truth its cameras observed (the
    corrections then name the reconstruction's rasters, which the retrain trains on)."""
    site = as_validation_site(entry)
    rasters = load_site_rasters(site.rasters)
    vectors, queue = review_queue(propose(rasters), MIN_CONFIDENCE)
    truth = (
        observed_true_polylines(site.site, rasters, site.frame)
        if site.reconstructed
        else true_polylines(site.site)
    )
    log = work_queue(queue, truth, SimulationConfig(), ActionCosts())
    reviewed: list[tuple[Vector, str]] = []
    for index, decision in queue.verdicts.items():
        proposal = vectors[index]
        if decision.kind == "fix" and decision.points is not None:
            cls = decision.relabel or proposal.cls
            reviewed.append((Vector(cls, np.asarray(decision.points), 1.0), "fixed"))
        else:
            reviewed.append((proposal, {"accept": "accepted", "reject": "rejected"}[decision.kind]))
        if decision.split_off is not None:  # the part split off is a new element, as the editor's split makes
            reviewed.append((Vector(proposal.cls, np.asarray(decision.split_off.points), 1.0), "accepted"))
    reviewed += [(Vector(t.cls, t.points, 1.0), "accepted") for t in queue.drawn]
    georeference = Georeference.of(rasters.georeference, site_origin_xy=rasters.origin_xy)
    labelled = proposals_as_annotations([v for v, _ in reviewed], georeference, site.site.name, "annotator")
    states = [state for v, state in reviewed if simple_geometry(v) is not None]
    elements = [e.with_changes(review_state=s) for e, s in zip(labelled.elements, states, strict=True)]
    counts = {k: int(v) for k, v in log.counts.items()}
    return Corrections(site.rasters, labelled.model_copy(update={"elements": elements})), counts


def measure(propose: Proposer, sites: list[Path]) -> dict[str, Any]:
    """Held-out figures of one proposer: mAP clean and damaged, annotator time on clean rasters."""
    clean = evaluate_proposer(propose, sites)
    damaged = evaluate_proposer(on_damaged(propose), sites)
    review = review_time(propose, sites)
    return {
        "map_clean": clean["mean_ap"],
        "map_damaged": damaged["mean_ap"],
        "class_ap_clean": clean["class_ap"],
        "class_ap_damaged": damaged["class_ap"],
        "annotator": review,
    }


def measure_model(registry: Path, sites: list[Path], reconstructions: list[ValidationSite]) -> dict[str, Any]:
    """The promoted model as the product proposes with it (rescored candidates, or the element-mask network's own
    traced masks, also on the reconstructed rasters of `reconstructions`), and an anchored model's own refined
    points."""
    if checkpoint_kind(registry) == MASK_KIND:
        masks = load_mask_checkpoint(registry)
        for site in [*sites, *map(truth_folder, reconstructions)]:
            ensure_unseen(masks, site)
        propose = product_proposer(masks.model)
        figures = {"version": masks.path.name, **measure(propose, sites)}
        if reconstructions:
            figures["reconstructed"] = reconstructed_figures(propose, reconstructions)
        return figures
    loaded = load_checkpoint(registry)
    for site in sites:
        ensure_unseen(loaded, site)
    figures = {"version": loaded.path.name, **measure(model_proposer(loaded.model, InferenceConfig()), sites)}
    if loaded.config.anchored:
        own = model_proposer(loaded.model, InferenceConfig(anchored_output="refined"))
        figures["own_points"] = measure(own, sites)
    return figures


def measure_rule_based(sites: list[Path], reconstructions: list[ValidationSite]) -> dict[str, Any]:
    """The rule-based proposer's held-out figures; on reconstructions its boundaries follow the road's edge, as
    `cama run` runs it there."""
    figures = measure(propose_rule_based, sites)
    if reconstructions:
        on_reconstruction = RuleConfig(boundary_source="road_edge")
        figures["reconstructed"] = reconstructed_figures(
            lambda rasters: propose_rule_based(rasters, on_reconstruction), reconstructions
        )
    return figures


def bootstrap_model(registry: Path, sites: list[Path], steps: int, refused: list[Path]) -> None:
    """Round 0 from scratch: an element-mask network trained on the generator's truth of a few `sites`, saved
    and promoted as the registry's first version (refusing to have seen any of `refused`)."""
    train_masks(
        MaskModelConfig(),
        MaskTrainConfig(steps=steps),
        sites,
        registry,
        validation_sites=refused,
        show_progress=False,
    )


def promoted_proposer(registry: Path) -> Proposer:
    """The registry's promoted model as the product proposes with it (the element-mask network with the
    product's settings: `product_proposer`)."""
    if checkpoint_kind(registry) == MASK_KIND:
        return product_proposer(load_mask_checkpoint(registry).model)
    return model_proposer(load_checkpoint(registry).model, InferenceConfig())


def retrain_round(
    registry: Path,
    corrections: list[Corrections],
    validation: list[ValidationEntry],
    steps: int,
    replay: tuple[int, int, float],
    time_confidence: float,
    map_tolerance: float,
    start_version: str | None,
) -> RetrainResult:
    """One retraining of the registry's network on corrections, behind both gates (the time saving at
    `time_confidence`, the candidate's mAP at least the current one's less `map_tolerance`); the element-mask
    network rehearses `replay` = (generator sites, reconstructions, share) of its own training sites and is
    trained from `start_version` (None: the promoted version)."""
    if checkpoint_kind(registry) == MASK_KIND:
        config = MaskRetrainConfig(
            train=MaskTrainConfig(steps=steps, learning_rate=3e-4, damaged_copies=2),
            replay_sites=replay[0],
            replay_reconstructions=replay[1],
            replay_share=replay[2],
            time_confidence=time_confidence,
            tolerance=map_tolerance,
            start_version=start_version,
        )
        return retrain_masks_from_corrections(registry, corrections, validation, config, review=review_time)
    retrain = RetrainConfig(
        train=TrainConfig(steps=steps, learning_rate=2e-4),
        time_confidence=time_confidence,
        tolerance=map_tolerance,
    )
    return retrain_from_corrections(registry, corrections, validation, retrain, review=review_time)


def plot_path(out: Path) -> Path:
    """The plot beside the figures: X.json -> X/rounds.png."""
    return out.with_suffix("") / "rounds.png"


def recon_map(figures: dict[str, Any]) -> float | None:
    """Chamfer mAP on the reconstructed rasters against the observed truth, when measured."""
    recon = figures.get("reconstructed")
    return None if recon is None else float(recon["observed_truth"]["mean_ap"])


def plot(rounds: list[dict[str, Any]], rule: dict[str, Any], path: Path) -> None:
    """mAP (clean, damaged, reconstructed) and the annotator's speed-up (BEV, reconstructed) per round, the
    rule-based proposer dashed."""
    ks = [r["round"] for r in rounds]
    own = [r["heldout"].get("own_points") for r in rounds]
    fig, (ax_map, ax_speed) = plt.subplots(1, 2, figsize=(10, 4))
    for key, colour in (("map_clean", "tab:blue"), ("map_damaged", "tab:orange")):
        ax_map.plot(ks, [r["heldout"][key] for r in rounds], "o-", color=colour, label=f"model {key[4:]}")
        if all(own):
            ax_map.plot(ks, [o[key] for o in own], "s:", color=colour, label=f"own points {key[4:]}")
        ax_map.axhline(rule[key], color=colour, linestyle="--", label=f"rule-based {key[4:]}")
    recon = [recon_map(r["heldout"]) for r in rounds]
    rule_recon = recon_map(rule)
    if rule_recon is not None and all(v is not None for v in recon):
        ax_map.plot(ks, recon, "o-", color="tab:green", label="model reconstructed")
        ax_map.axhline(rule_recon, color="tab:green", linestyle="--", label="rule-based reconstructed")
    ax_map.set(xlabel="round", ylabel="held-out Chamfer mAP", title="proposal quality")
    ax_map.legend(fontsize=7)
    ax_speed.plot(ks, [r["heldout"]["annotator"]["speed_up"] for r in rounds], "o-", label="model BEV")
    if all(own):
        ax_speed.plot(ks, [o["annotator"]["speed_up"] for o in own], "s:", label="own points BEV")
    ax_speed.axhline(rule["annotator"]["speed_up"], linestyle="--", label="rule-based BEV")
    if "reconstructed" in rule and all("reconstructed" in r["heldout"] for r in rounds):
        recon_speed = [r["heldout"]["reconstructed"]["annotator"]["speed_up"] for r in rounds]
        ax_speed.plot(ks, recon_speed, "o-", color="tab:green", label="model reconstructed")
        ax_speed.axhline(
            rule["reconstructed"]["annotator"]["speed_up"],
            color="tab:green",
            linestyle="--",
            label="rule-based reconstructed",
        )
    ax_speed.set(xlabel="round", ylabel="speed-up over drawing", title="simulated annotator, held-out sites")
    ax_speed.legend(fontsize=8)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)


def summary(figures: dict[str, Any]) -> str:
    """One line of held-out figures."""
    recon = recon_map(figures)
    line = f"{figures['map_clean']:.3f} clean / {figures['map_damaged']:.3f} damaged"
    line += "" if recon is None else f" / {recon:.3f} reconstructed"
    return line + f", {figures['annotator']['speed_up']:.2f}x"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--checkpoint", type=Path, default=Path("models/vma/checkpoints"))
    parser.add_argument(
        "--bootstrap-seeds",
        help="round 0: an element-mask network trained here on these BEV sites' truth ('A-B'), not --checkpoint",
    )
    parser.add_argument("--bootstrap-steps", type=int, default=600)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument(
        "--steps", type=int, default=300, help="fine-tuning batches per round (the job's default)"
    )
    parser.add_argument("--new-seeds", default="4000-4002", help="one new site per round ('A-B')")
    parser.add_argument(
        "--new-recon-site",
        type=Path,
        action="append",
        default=[],
        help="synthetic site with `cama run` done, one per round in place of --new-seeds: proposed on and corrected "
        + "on its reconstructed rasters, as the product does (repeatable)",
    )
    parser.add_argument("--val-seeds", default="3000-3002", help="the gate's validation sites")
    parser.add_argument("--heldout-seeds", default="2000-2004", help="measured after every round")
    parser.add_argument(
        "--recon-site",
        type=Path,
        action="append",
        help="synthetic site with `cama run` done, measured on its reconstructed rasters after every round "
        + "(element-mask network; repeatable; default: data/synthetic/default and random-9001)",
    )
    parser.add_argument(
        "--gate-recon-site",
        type=Path,
        action="append",
        default=[],
        help="synthetic site with `cama run` done that the gate scores on its reconstructed rasters, beside the "
        + "--val-seeds BEV sites ('' for none); repeatable; never one of --recon-site",
    )
    parser.add_argument(
        "--replay-sites",
        type=int,
        default=MaskRetrainConfig.replay_sites,
        help="element-mask retraining: how many of the model's own training sites it rehearses (0: none)",
    )
    parser.add_argument(
        "--replay-reconstructions",
        type=int,
        default=MaskRetrainConfig.replay_reconstructions,
        help="element-mask retraining: how many of the reconstructions the model trained on it rehearses (0: none)",
    )
    parser.add_argument(
        "--replay-share",
        type=float,
        default=MaskRetrainConfig.replay_share,
        help="element-mask retraining: the share of crops from the rehearsed sites",
    )
    parser.add_argument(
        "--time-confidence",
        type=float,
        default=TIME_CONFIDENCE,
        help="the gate's confidence in a time saving over its sites (0: the totals alone decide)",
    )
    parser.add_argument(
        "--map-tolerance",
        type=float,
        default=MaskRetrainConfig.tolerance,
        help="the mAP gate: a candidate passes with at least the current model's validation mAP less this",
    )
    parser.add_argument(
        "--propose-on",
        choices=("clean", "damaged"),
        default="damaged",
        help="the new BEV sites' rasters as they are or damaged (reconstructions are proposed on as they are)",
    )
    parser.add_argument("--corrections", choices=("all", "latest"), default="all")
    parser.add_argument(
        "--retrain-from",
        choices=("promoted", "first"),
        default="promoted",
        help="element-mask retraining: fine-tune the promoted model (the job's default), or retrain round 0's model "
        + "on every correction so far for --steps per corrected site (with --corrections all)",
    )
    parser.add_argument("--site-root", type=Path, default=Path("data/vma/loop"))
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--out", type=Path, default=RESULTS / "vma_loop.json")
    parser.add_argument(
        "--plot-only", action="store_true", help="redraw the plot from the results file, measuring nothing"
    )
    parser.add_argument(
        "--keep-registry",
        type=Path,
        default=None,
        help="copy the loop's registry (every candidate, the promoted one marked) to this new folder at the end",
    )
    args = parser.parse_args()
    if args.plot_only:
        recorded = json.loads(args.out.read_text(encoding="utf-8"))
        plot(recorded["rounds"], recorded["rule_based"], plot_path(args.out))
        return
    torch.set_num_threads(args.threads)
    new_sites: list[ValidationEntry] = [reconstruction_of(site) for site in args.new_recon_site]
    if not new_sites:
        new_sites += ensure_bev_sites(seed_range(args.new_seeds), args.site_root)
    new_sites = new_sites[: args.rounds]
    if len(new_sites) < args.rounds:
        raise SystemExit(f"the new sites ({len(new_sites)}) are fewer than the {args.rounds} rounds")
    validation = ensure_bev_sites(seed_range(args.val_seeds), args.site_root)
    heldout = ensure_bev_sites(seed_range(args.heldout_seeds), args.site_root)
    recon = args.recon_site or [Path("data/synthetic/default"), Path("data/synthetic/random-9001")]
    if set(map(Path.resolve, args.gate_recon_site)) & set(map(Path.resolve, recon)):
        raise SystemExit("--gate-recon-site: a site the loop measures (--recon-site) cannot also validate it")
    if set(map(Path.resolve, args.new_recon_site)) & set(map(Path.resolve, [*recon, *args.gate_recon_site])):
        raise SystemExit("--new-recon-site: a site the loop corrects cannot also measure or validate it")
    if args.retrain_from == "first" and args.corrections != "all":
        raise SystemExit("--retrain-from first retrains round 0's model, so it needs --corrections all")
    gate_recon = [reconstruction_of(site) for site in args.gate_recon_site]
    if not validation and not gate_recon:
        raise SystemExit("the gate needs validation sites: --val-seeds or --gate-recon-site")
    scratch = Path(tempfile.mkdtemp(prefix="bench-vma-loop-"))
    registry = scratch / "registry"
    started = time.perf_counter()
    if args.bootstrap_seeds:
        bootstrap_sites = ensure_bev_sites(seed_range(args.bootstrap_seeds), args.site_root)
        bootstrap_model(
            registry,
            bootstrap_sites,
            args.bootstrap_steps,
            [*map(truth_folder, new_sites), *validation, *heldout, *recon, *args.gate_recon_site],
        )
        start = (
            f"element-mask network trained on BEV sites {args.bootstrap_seeds}, {args.bootstrap_steps} steps"
        )
        print(f"round 0 trained in {time.perf_counter() - started:.0f} s")
    else:
        shipped = current_version(args.checkpoint)
        shutil.copytree(shipped, registry / shipped.name)
        promote(registry, shipped.name)
        start = str(shipped)
    if checkpoint_kind(registry) != MASK_KIND:
        recon = []  # the reconstructed condition is measured for the element-mask network only
        if args.retrain_from == "first":
            raise SystemExit(
                "--retrain-from first: only the element-mask network can be retrained from round 0"
            )
    start_version = current_version(registry).name if args.retrain_from == "first" else None
    # only new BEV sites are damaged: a reconstruction is proposed on as it is
    damage = args.propose_on == "damaged" and not args.new_recon_site
    propose_on = on_damaged if damage else (lambda propose: propose)
    held_out_reconstructions = [reconstruction_of(site) for site in recon]  # made once, measured every round
    rule = measure_rule_based(heldout, held_out_reconstructions)
    print(f"rule-based: {summary(rule)}")
    rounds: list[dict[str, Any]] = [
        {"round": 0, "heldout": measure_model(registry, heldout, held_out_reconstructions)}
    ]
    print(f"round 0: {summary(rounds[0]['heldout'])}")
    corrected: list[Corrections] = []
    try:
        for k, site in enumerate(new_sites, start=1):
            round_started = time.perf_counter()
            corrections, review_counts = corrections_of(site, propose_on(promoted_proposer(registry)))
            corrected = [*corrected, corrections] if args.corrections == "all" else [corrections]
            result = retrain_round(
                registry,
                corrected,
                [*validation, *gate_recon],
                args.steps * len(corrected) if start_version else args.steps,
                (args.replay_sites, args.replay_reconstructions, args.replay_share),
                args.time_confidence,
                args.map_tolerance,
                start_version,
            )
            retrain_s = time.perf_counter() - round_started
            rounds.append(
                {
                    "round": k,
                    "corrected_site": str(site),
                    "trained_on": [str(c.site) for c in corrected],
                    "review_counts": review_counts,
                    "candidate": result.candidate.name,
                    "trained_from": start_version or "promoted",
                    "promoted": result.promoted,
                    "gate": {
                        "current": result.current_metrics,
                        "candidate": result.candidate_metrics,
                        "saving_confidence": review_saving_confidence(
                            result.current_metrics.get("review", {}),
                            result.candidate_metrics.get("review", {}),
                        ),
                    },
                    "retrain_seconds": round(retrain_s, 1),
                    "heldout": measure_model(registry, heldout, held_out_reconstructions),
                }
            )
            print(
                f"round {k}: {result.candidate.name} {'promoted' if result.promoted else 'kept out'} "
                f"({retrain_s:.0f} s); held-out {summary(rounds[-1]['heldout'])}"
            )
        if args.keep_registry is not None:
            shutil.copytree(registry, args.keep_registry)
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    plot(rounds, rule, plot_path(args.out))
    origin = (
        f"--bootstrap-seeds {args.bootstrap_seeds} --bootstrap-steps {args.bootstrap_steps}"
        if args.bootstrap_seeds
        else f"--checkpoint {args.checkpoint}"
    )
    report = {
        "command": f"python bench/vma_loop.py {origin} "
        + f"--rounds {args.rounds} --steps {args.steps} "
        + (
            "".join(f"--new-recon-site {s} " for s in args.new_recon_site)
            if args.new_recon_site
            else f"--new-seeds {args.new_seeds} "
        )
        + f"--val-seeds '{args.val_seeds}' --heldout-seeds {args.heldout_seeds} "
        + "".join(f"--recon-site {s} " for s in recon)
        + "".join(f"--gate-recon-site {s} " for s in args.gate_recon_site)
        + f"--replay-sites {args.replay_sites} "
        + (f"--replay-reconstructions {args.replay_reconstructions} " if args.replay_reconstructions else "")
        + f"--replay-share {args.replay_share} "
        + (f"--time-confidence {args.time_confidence} " if args.time_confidence != TIME_CONFIDENCE else "")
        + (f"--map-tolerance {args.map_tolerance} " if args.map_tolerance else "")
        + (f"--retrain-from {args.retrain_from} " if args.retrain_from != "promoted" else "")
        + f"--propose-on {args.propose_on} --corrections {args.corrections} --threads {args.threads}",
        "start": start,
        "rule_based": rule,
        "rounds": rounds,
        "machine": {"cpu_threads": args.threads, "platform": platform.platform(), "device": "cpu"},
        "seconds": round(time.perf_counter() - started, 1),
    }
    args.out.write_text(json.dumps(report, indent=1) + "\n", encoding="utf-8")
    print(f"wrote {args.out} and {plot_path(args.out)}")


if __name__ == "__main__":
    main()
