"""`cama run`: the whole reconstruction path (wigo ... VMA proposals) for a nuScenes-layout data set."""

from pathlib import Path
from typing import Annotated

import typer

from cama_pipeline.console import bad_input, console, failure


def run_command(
    dataset: Annotated[Path, typer.Argument(help="Data set root (nuScenes layout).")],
    workspace: Annotated[
        Path | None, typer.Option(help="Workspace folder; default <data set root's parent>/workspace.")
    ] = None,
    executor: Annotated[str, typer.Option(help="Where SfM clips run: local or ray.")] = "local",
    workers: Annotated[int, typer.Option(min=1, help="SfM processes.")] = 2,
    max_features: Annotated[
        int | None, typer.Option(help="SIFT keypoints per image (features stage default if omitted).")
    ] = None,
    proposer: Annotated[str, typer.Option(help="learned (the checkpoint) or rule.")] = "learned",
    checkpoint: Annotated[
        Path | None,
        typer.Option(
            help="VMA checkpoint registry or version folder; default: the model shipped with the package."
        ),
    ] = None,
    stop_after: Annotated[str, typer.Option(help="Last stage to run.")] = "propose",
    overwrite: Annotated[bool, typer.Option(help="Recompute every stage even if up to date.")] = False,
) -> None:
    """Run every stage in order, each skipping what is up to date; print the time per stage."""
    from cama_studio.pipeline import STAGES, PipelineConfig, PipelineError, run

    try:
        if executor not in ("local", "ray"):
            raise ValueError(f"--executor must be local or ray, got {executor!r}")
        if proposer not in ("learned", "rule"):
            raise ValueError(f"--proposer must be learned or rule, got {proposer!r}")
        config = PipelineConfig(
            executor="ray" if executor == "ray" else "local",
            workers=workers,
            max_features=max_features,
            proposer="rule" if proposer == "rule" else "learned",
            checkpoint=checkpoint,
        )
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
        console.print(f"  {stage:<10} {seconds:8.1f} s")
    for site_id, path in result.proposals.items():
        console.print(f"[green]proposals[/green] {site_id}: {path}")
    if result.checkpoint is not None:
        from models.vma.shipped import checkpoint_label  # torch: only once a learned proposer ran

        console.print(f"  VMA checkpoint {checkpoint_label(result.checkpoint)}")
