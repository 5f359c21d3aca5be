"""`cama train-masks`: the element-mask network's training command (a thin layer over `train_masks`)."""

from pathlib import Path
from typing import Annotated

import typer

from cama_pipeline.console import bad_input, console
from models.vma.bev_sites import ensure_bev_sites
from models.vma.checkpoint import CheckpointError
from models.vma.commands import BevRoot, BevSeeds, TrainingSites, seed_range
from models.vma.element_masks.checkpoint import load_mask_checkpoint
from models.vma.element_masks.config import MaskModelConfig, MaskTrainConfig
from models.vma.element_masks.train import train_masks
from models.vma.validation import ValidationEntry, reconstruction_of


def train_masks_command(
    registry: Annotated[
        Path, typer.Option(help="Element-mask checkpoint registry to add the new version to.")
    ],
    site: TrainingSites = None,
    bev_seeds: BevSeeds = "",
    bev_root: BevRoot = Path("data/vma/train"),
    reconstructed_site: Annotated[
        list[Path] | None,
        typer.Option(
            help="Also train on the surface stage's rasters of this synthetic site (`cama synth`, then `cama run`), "
            "against the truth its cameras observed (repeatable)."
        ),
    ] = None,
    init: Annotated[Path | None, typer.Option(help="Continue from this element-mask checkpoint.")] = None,
    steps: Annotated[int, typer.Option(help="Training batches.")] = 3000,
    max_minutes: Annotated[
        float, typer.Option(help="Time budget; training stops at --steps or here.")
    ] = 40.0,
    damaged_copies: Annotated[
        int, typer.Option(help="Damaged copies of every site beside the clean one.")
    ] = 3,
    reconstruction_share: Annotated[
        float | None,
        typer.Option(
            help="Share of the training crops drawn from the --reconstructed-site sites (default: every site alike)."
        ),
    ] = None,
    seed: Annotated[int, typer.Option(help="Random seed.")] = 0,
    threads: Annotated[int, typer.Option(help="CPU threads torch trains with.")] = 2,
) -> None:
    """Train the element-mask VMA network (BEV segmentation, vectorised afterwards) as a new promoted version."""
    try:
        sites: list[ValidationEntry] = [*(site or []), *ensure_bev_sites(seed_range(bev_seeds), bev_root)]
        sites += [reconstruction_of(path) for path in reconstructed_site or []]
        parent = load_mask_checkpoint(init) if init is not None else None
        folder = train_masks(
            parent.model.config if parent is not None else MaskModelConfig(),
            MaskTrainConfig(
                steps=steps,
                max_seconds=max_minutes * 60,
                damaged_copies=damaged_copies,
                seed=seed,
                threads=threads,
            ),
            sites,
            registry,
            parent=parent,
            reconstruction_share=reconstruction_share,
        )
    except (ValueError, FileNotFoundError, CheckpointError) as err:
        raise bad_input(err) from err
    console.print(f"[green]checkpoint[/green] {folder} (promoted)")
