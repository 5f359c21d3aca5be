"""`cama run`: the whole reconstruction path (wigo ... VMA proposals) for a nuScenes-layout data set."""

from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from cama_pipeline.console import bad_input, console, failure

if TYPE_CHECKING:
    from cama_studio.config import PipelineConfig


def run_command(
    dataset: Annotated[
        Path | None,
        typer.Argument(
            help="Data set root (nuScenes layout); not needed with --print-config.", show_default=False
        ),
    ] = None,
    workspace: Annotated[
        Path | None, typer.Option(help="Workspace folder; default <data set root's parent>/workspace.")
    ] = None,
    config_file: Annotated[
        Path | None,
        typer.Option(
            "--config",
            help="TOML (or YAML) file setting run choices and any stage parameter ([wigo], [sfm], ... tables); "
            "see --print-config for every key. The options below override it.",
        ),
    ] = None,
    print_config: Annotated[
        bool, typer.Option(help="Print the effective configuration as TOML (a --config file) and exit.")
    ] = False,
    executor: Annotated[str | None, typer.Option(help="Where SfM clips run: local or ray.")] = None,
    workers: Annotated[int | None, typer.Option(min=1, help="SfM processes.")] = None,
    max_features: Annotated[
        int | None, typer.Option(help="SIFT keypoints per image (sets features.max_num_features).")
    ] = None,
    proposer: Annotated[
        str | None,
        typer.Option(
            help="masks (the element-mask network, default), learned (the MapTR-style model) or rule."
        ),
    ] = None,
    checkpoint: Annotated[
        Path | None,
        typer.Option(
            help="VMA checkpoint registry or version folder; default: the model shipped with the package."
        ),
    ] = None,
    masks: Annotated[
        str | None,
        typer.Option(
            help="Image masks: auto (the data set's, else the workspace's predicted, else imported; runs the "
            "segmenter when there are none), dataset, predicted, imported or a folder (sets masks)."
        ),
    ] = None,
    scene: Annotated[
        list[str] | None,
        typer.Option(
            "--scene", help="Only this scene (repeatable; sets scenes). Default: every scene of the data set."
        ),
    ] = None,
    stop_after: Annotated[str, typer.Option(help="Last stage to run.")] = "propose",
    overwrite: Annotated[bool, typer.Option(help="Recompute every stage even if up to date.")] = False,
) -> None:
    """Run every stage in order, each skipping what is up to date; print the time per stage.

    Without --config every stage runs with its defaults (local executor, 2 workers, the element-mask
    network proposing)."""
    from cama_studio.config import dump_toml
    from cama_studio.pipeline import STAGES, PipelineError, run

    try:
        config = effective_config(
            config_file, executor, workers, max_features, proposer, checkpoint, masks, scene
        )
        if print_config:
            console.out(dump_toml(config), end="", highlight=False)
            return
        if dataset is None:
            raise ValueError("missing argument DATASET (the data set root)")
        result = run(
            dataset,
            workspace,
            config,
            stop_after=stop_after,
            overwrite=overwrite,
            on_stage=lambda stage: console.rule(
                f"[bold]{stage}[/bold] ({STAGES.index(stage) + 1}/{len(STAGES)})"
            ),
        )
    except PipelineError as err:  # the data set or checkpoint at fault (2), or a stage that broke (1)
        raise (bad_input(err) if err.bad_input else failure(err)) from err
    except ValueError as err:
        raise bad_input(err) from err
    for stage, seconds in result.seconds.items():
        skipped = f"  skipped: {result.skipped[stage]}" if stage in result.skipped else ""
        console.print(f"  {stage:<10} {seconds:8.1f} s{skipped}")
    for site_id, path in result.proposals.items():
        console.print(f"[green]proposals[/green] {site_id}: {path}")
    if result.checkpoint is not None:
        from models.vma.shipped import checkpoint_label  # torch: only once a learned proposer ran

        console.print(f"  VMA checkpoint {checkpoint_label(result.checkpoint)}")


def effective_config(
    config_file: Path | None,
    executor: str | None,
    workers: int | None,
    max_features: int | None,
    proposer: str | None,
    checkpoint: Path | None,
    masks: str | None = None,
    scenes: list[str] | None = None,
) -> "PipelineConfig":
    """The --config file's configuration (the defaults without one), with the options given on top; ValueError
    naming the option or the file and key at fault."""
    from dataclasses import replace

    from cama_studio.config import PipelineConfig, load_config

    config = load_config(config_file) if config_file is not None else PipelineConfig()
    if executor is not None:
        if executor not in ("local", "ray"):
            raise ValueError(f"--executor must be local or ray, got {executor!r}")
        config = replace(config, executor="ray" if executor == "ray" else "local")
    if proposer is not None:
        config = replace(config, proposer=proposer)  # type: ignore[arg-type]  # PipelineConfig checks it
    if workers is not None:
        config = replace(config, workers=workers)
    if checkpoint is not None:
        config = replace(config, checkpoint=checkpoint)
    if masks is not None:
        try:
            config = replace(config, masks=masks)
        except ValueError as err:
            raise ValueError(f"--masks: {err}") from None
    if scenes:
        try:
            config = replace(config, scenes=tuple(scenes))
        except ValueError as err:
            raise ValueError(f"--scene: {err}") from None
    if max_features is not None:
        try:
            config = replace(config, features=replace(config.features, max_num_features=max_features))
        except ValueError as err:
            raise ValueError(f"--max-features: {err}") from None
    return config
