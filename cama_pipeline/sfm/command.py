"""`cama sfm`: odometry-guided SfM of every site, clip by clip in parallel, merged into one model per site."""

from typing import Annotated

import typer

from cama_pipeline.cli_options import DatasetArg, MasksOpt, OverwriteOpt, WorkspaceOpt
from cama_pipeline.console import INPUT_ERRORS, bad_input, console, failure
from cama_pipeline.sfm.config import SfmConfig
from cama_pipeline.sfm.errors import SfmError
from cama_pipeline.sfm.executor import EXECUTORS
from cama_pipeline.sfm.stage import run


def sfm_command(
    dataset: DatasetArg,
    workspace: WorkspaceOpt = None,
    preset: Annotated[
        str, typer.Option(help="plain (guided + BA), rigid (+ rigid BA) or iterative (+ iterative BA).")
    ] = "iterative",
    executor: Annotated[
        str, typer.Option(help="Where clips run: local (process pool) or ray (local Ray instance).")
    ] = "local",
    workers: Annotated[int, typer.Option(min=1, help="Clips reconstructed at once.")] = 2,
    masks: MasksOpt = "auto",
    overwrite: OverwriteOpt = False,
) -> None:
    """Reconstruct each site: every clip on its own from the WIGO poses, then merged and adjusted as one."""
    if executor not in EXECUTORS:
        raise bad_input(f"--executor must be one of {', '.join(EXECUTORS)}, got {executor!r}")
    try:
        config = SfmConfig.preset(preset)
        result = run(
            config, dataset, workspace, executor=executor, workers=workers, masks=masks, overwrite=overwrite
        )
    except INPUT_ERRORS as err:
        raise bad_input(err) from err
    except SfmError as err:  # every clip failed: the reconstruction, not its input
        raise failure(err) from err
    for site in result.items:
        merged, clips = site.report["merged"], site.report["clips"]
        failed = [scene for scene, clip in clips.items() if clip["status"] != "ok"]
        state = "up to date" if site.skipped else f"{site.report['seconds']['total']:.1f} s"
        console.print(
            f"[green]{site.name}[/green]: {merged['registered_images']} of {merged['images']} images, "
            f"{merged['points']} points, {merged['reprojection_error_px']:.2f} px, "
            f"{len(clips) - len(failed)} of {len(clips)} clips ({state}) -> {site.path}"
        )
        if failed:
            console.print(f"  [yellow]clips left out (SfM failed): {', '.join(failed)}[/yellow]")
