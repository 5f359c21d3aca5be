"""The VMA commands of the `cama` CLI: propose, train, retrain, vma-eval, vma-split (thin layers over the API)."""

import logging
from pathlib import Path
from typing import Annotated

import typer

from annotations import AnnotationSet
from cama_pipeline.cli_options import DatasetArg
from cama_pipeline.console import bad_input, console
from cama_pipeline.data import DatasetError
from cama_pipeline.evaluate.inputs import EvaluationInputError
from cama_pipeline.io import atomic_write_json
from models.vma.bev_sites import ensure_bev_sites
from models.vma.checkpoint import CheckpointError, ensure_unseen, load_checkpoint, promote
from models.vma.config import ANCHORED_MODEL, ModelConfig, TrainConfig
from models.vma.element_masks.checkpoint import load_mask_checkpoint
from models.vma.element_masks.propose import predict_site_masks
from models.vma.evaluate import evaluate_proposer
from models.vma.infer import InferenceConfig, predict_site
from models.vma.propose import PROPOSERS, propose
from models.vma.retrain import Corrections, RetrainConfig, gate_checkpoint, retrain_from_corrections
from models.vma.rule_based import RuleConfig, propose_rule_based
from models.vma.shipped import SHIPPED_MASK_REGISTRY, checkpoint_label, resolve_checkpoint, seed_registry
from models.vma.split import SplitConfig, split_dataset
from models.vma.train import train

logger = logging.getLogger(__name__)

_ERRORS = (ValueError, FileNotFoundError, CheckpointError, EvaluationInputError)


TrainingSites = Annotated[
    list[Path] | None, typer.Option("--site", help="Training site folder with vector_map.json (repeatable).")
]
BevSeeds = Annotated[str, typer.Option(help="Also train on BEV-only synthetic sites of these seeds ('A-B').")]
BevRoot = Annotated[Path, typer.Option(help="Where BEV-only sites are generated (cached).")]
"""The training data options `cama train` and `cama train-masks` share."""


def seed_range(text: str) -> list[int]:
    """'1000-1007' or '1000,1003' as a list of seeds."""
    try:
        if "-" in text:
            lo, hi = (int(v) for v in text.split("-", 1))
            return list(range(lo, hi + 1))
        return [int(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise ValueError(f"--bev-seeds: expected 'A-B' or 'A,B,...', got {text!r}") from None


def propose_command(
    site: Annotated[Path, typer.Argument(help="Site folder (rasters in it or in ground_truth/bev/).")],
    out: Annotated[Path, typer.Option(help="Proposals JSON (an annotation set) to write.")] = Path(
        "proposals.json"
    ),
    proposer: Annotated[
        str,
        typer.Option(
            help="masks (the shipped element-mask network unless --checkpoint), learned (the shipped MapTR-style "
            "model unless --checkpoint) or rule."
        ),
    ] = "masks",
    checkpoint: Annotated[
        Path | None,
        typer.Option(
            help="Checkpoint version folder or registry; default: the model shipped with the package."
        ),
    ] = None,
    min_confidence: Annotated[float, typer.Option(help="Drop proposals scoring lower.")] = 0.1,
    boundary_source: Annotated[
        str,
        typer.Option(
            help="auto (road_edge on a surface stage's rasters, as `cama run` does; else curb), curb (generator "
            "rasters) or road_edge (reconstructed rasters, smeared curbs)."
        ),
    ] = "auto",
    overwrite: Annotated[bool, typer.Option(help="Propose again even if the output is up to date.")] = False,
) -> None:
    """Propose map vectors with confidence for a whole site from its BEV rasters."""
    try:
        if proposer not in PROPOSERS:
            raise ValueError(f"--proposer must be one of {', '.join(PROPOSERS)}, got {proposer!r}")
        if boundary_source not in ("auto", "curb", "road_edge"):
            raise ValueError(
                f"--boundary-source must be 'auto', 'curb' or 'road_edge', got {boundary_source!r}"
            )
        result = propose(
            site,
            out,
            proposer=proposer,  # type: ignore[arg-type]  # checked against PROPOSERS above
            checkpoint=checkpoint,
            min_confidence=min_confidence,
            rule=None
            if boundary_source == "auto"
            else RuleConfig(boundary_source="road_edge" if boundary_source == "road_edge" else "curb"),
            overwrite=overwrite,
        )
    except _ERRORS as err:
        raise bad_input(err) from err
    state = (
        "up to date, nothing done"
        if result.skipped
        else f"{result.count} proposals in {result.seconds:.1f} s"
    )
    console.print(f"[green]proposals[/green] {result.out} ({state})")
    if result.checkpoint is not None:
        console.print(f"  VMA checkpoint {checkpoint_label(result.checkpoint)}")


def train_command(
    registry: Annotated[
        Path,
        typer.Option(
            help="Checkpoint registry to add the new version to (models/vma/checkpoints in a checkout: the "
            "shipped model)."
        ),
    ],
    site: TrainingSites = None,
    bev_seeds: BevSeeds = "",
    bev_root: BevRoot = Path("data/vma/train"),
    init: Annotated[
        Path | None, typer.Option(help="Continue from this checkpoint (same model config).")
    ] = None,
    steps: Annotated[int, typer.Option(help="Training batches.")] = 2000,
    max_minutes: Annotated[
        float, typer.Option(help="Time budget; training stops at --steps or here.")
    ] = 40.0,
    batch_size: Annotated[int, typer.Option(help="Patches per batch.")] = 8,
    seed: Annotated[int, typer.Option(help="Random seed.")] = 0,
    anchored: Annotated[
        bool, typer.Option(help="Anchored model (queries from rule-based candidates) or free MapTR queries.")
    ] = True,
    procedural_share: Annotated[float, typer.Option(help="Share of procedural patches per batch.")] = 0.0,
    val: Annotated[
        list[Path] | None,
        typer.Option(help="Validation site (repeatable): promote only if mAP beats the promoted version."),
    ] = None,
) -> None:
    """Train the learned VMA model and save it as a new checkpoint version (promoted, or gated with --val)."""
    try:
        sites = list(site or []) + ensure_bev_sites(seed_range(bev_seeds), bev_root)
        folder = train(
            ANCHORED_MODEL if anchored else ModelConfig(),
            TrainConfig(
                steps=steps,
                batch_size=batch_size,
                seed=seed,
                max_seconds=max_minutes * 60,
                procedural_share=procedural_share,
            ),
            sites,
            registry,
            init=init,
            promote_result=not val,
            validation_sites=list(val or []),
        )
        promoted = not val or _gate_new(registry, folder, list(val or []))
    except _ERRORS as err:
        raise bad_input(err) from err
    console.print(f"[green]checkpoint[/green] {folder} ({'promoted' if promoted else 'not promoted: gate'})")


def _gate_new(registry: Path, folder: Path, val: list[Path]) -> bool:
    """Promote a newly trained version if it beats the promoted one (any config) on `val`; True when promoted."""
    if not (registry / "current.json").is_file():
        promote(registry, folder.name)
        return True
    promoted, current, candidate = gate_checkpoint(registry, folder, val, allow_new_config=True)
    console.print(f"validation mAP {candidate['mean_ap']} vs promoted {current['mean_ap']}")
    return promoted


def retrain_command(
    corrections: Annotated[
        list[str],
        typer.Option(
            help="SITE=ANNOTATIONS.json: a site folder and its reviewed annotation set (repeatable)."
        ),
    ],
    val: Annotated[list[Path], typer.Option(help="Validation site with ground truth (repeatable).")],
    registry: Annotated[
        Path,
        typer.Option(
            help="Checkpoint registry (its promoted version is fine-tuned, the new version added); an empty or "
            "missing folder is first seeded with a copy of the shipped model."
        ),
    ],
    steps: Annotated[int, typer.Option(help="Fine-tuning batches.")] = 300,
    tolerance: Annotated[float, typer.Option(help="Promote when mAP >= current mAP - tolerance.")] = 0.0,
) -> None:
    """Fine-tune on accepted/fixed annotations (rejected = negatives); promote only if validation mAP holds."""
    try:
        items = []
        for pair in corrections:
            if "=" not in pair:
                raise ValueError(f"--corrections: expected SITE=ANNOTATIONS.json, got {pair!r}")
            site, annotations = pair.split("=", 1)
            items.append(Corrections(Path(site), AnnotationSet.read_json(Path(annotations))))
        config = RetrainConfig(train=TrainConfig(steps=steps, learning_rate=2e-4), tolerance=tolerance)
        registry = seed_registry(registry)
        result = retrain_from_corrections(registry, items, val, config, show_progress=True)
    except _ERRORS as err:
        raise bad_input(err) from err
    verdict = "[green]promoted[/green]" if result.promoted else "[yellow]not promoted[/yellow] (gate)"
    console.print(
        f"candidate {result.candidate}: mAP {result.candidate_metrics['mean_ap']} vs current "
        f"{result.current_metrics['mean_ap']} -> {verdict}"
    )


def vma_eval_command(
    site: Annotated[list[Path], typer.Argument(help="Site folders with ground truth (vector_map.json).")],
    proposer: Annotated[str, typer.Option(help="masks (element-mask network), learned or rule.")] = "masks",
    checkpoint: Annotated[
        Path | None,
        typer.Option(
            help="Checkpoint version folder or registry; default: the model shipped with the package."
        ),
    ] = None,
    out: Annotated[Path, typer.Option(help="JSON report to write.")] = Path("vma_eval.json"),
) -> None:
    """Chamfer-AP (0.5/1.0/1.5 m, per class and mean) and precision per confidence bin of a proposer; a network's
    checkpoint is refused (exit 2) on a site it trained on."""
    try:
        if proposer == "masks":
            version = resolve_checkpoint(checkpoint, SHIPPED_MASK_REGISTRY)
            console.print(f"element-mask checkpoint {checkpoint_label(version)}")
            masks = load_mask_checkpoint(version)
            for folder in site:
                ensure_unseen(masks, folder)
            report = evaluate_proposer(lambda r: predict_site_masks(masks.model, r), site)
        elif proposer == "learned":
            version = resolve_checkpoint(checkpoint)
            console.print(f"VMA checkpoint {checkpoint_label(version)}")
            loaded = load_checkpoint(version)
            for folder in site:
                ensure_unseen(loaded, folder)
            model = loaded.model
            report = evaluate_proposer(lambda r: predict_site(model, r, InferenceConfig()), site)
        elif proposer == "rule":
            report = evaluate_proposer(propose_rule_based, site)
        else:
            raise ValueError(f"--proposer must be one of {', '.join(PROPOSERS)}, got {proposer!r}")
    except _ERRORS as err:
        raise bad_input(err) from err
    atomic_write_json(out, report, indent=1)
    for cls, ap in report["class_ap"].items():
        console.print(f"  {cls:13s} AP {'-' if ap is None else f'{ap:.3f}'}")
    console.print(f"[green]mAP[/green] {report['mean_ap']}  (report: {out})")


def vma_split_command(
    dataset: DatasetArg,
    out: Annotated[Path, typer.Option(help="Split JSON to write.")] = Path("split.json"),
    val_share: Annotated[float, typer.Option(help="Target share of scenes in validation.")] = 0.25,
    overlap_m: Annotated[
        float, typer.Option(help="Scenes passing within this distance share a location.")
    ] = 50.0,
    seed: Annotated[int, typer.Option(help="Random seed of the group order.")] = 0,
) -> None:
    """Location-disjoint train/validation split of a data set's scenes."""
    try:
        split = split_dataset(dataset, out, SplitConfig(val_share, overlap_m, seed))
    except (*_ERRORS, DatasetError) as err:
        raise bad_input(err) from err
    console.print(f"[green]split[/green] {len(split.train)} train / {len(split.val)} val scenes -> {out}")
