"""`cama keyframes`: multi-view resync and keyframe selection over the WIGO poses in the workspace."""

from typing import Annotated

import typer
from rich.table import Table

from cama_pipeline.cli_options import DatasetArg, OverwriteOpt, ScenesOpt, WorkspaceOpt
from cama_pipeline.console import INPUT_ERRORS, bad_input, console
from cama_pipeline.keyframes.config import KeyframeConfig
from cama_pipeline.keyframes.stage import run


def keyframes_command(
    dataset: DatasetArg,
    workspace: WorkspaceOpt = None,
    scene: ScenesOpt = None,
    max_time_diff_ms: Annotated[float, typer.Option(help="Resync limit to the frame time.")] = 40.0,
    min_translation_m: Annotated[float, typer.Option(help="Keyframe after this much travel.")] = 2.0,
    min_rotation_deg: Annotated[float, typer.Option(help="Keyframe after this much turning.")] = 3.0,
    overwrite: OverwriteOpt = False,
) -> None:
    """Group camera images into frames (<= 40 ms) and choose keyframes by translation / rotation."""
    try:
        config = KeyframeConfig(
            max_time_diff_ms=max_time_diff_ms,
            min_translation_m=min_translation_m,
            min_rotation_deg=min_rotation_deg,
        )
        result = run(config, dataset, workspace, scenes=scene, overwrite=overwrite)
    except INPUT_ERRORS as err:
        raise bad_input(err) from err
    table = Table(title="keyframes")
    table.add_column("scene", no_wrap=True, min_width=10)
    for column in ("frames", "keyframes", "stationary", "path m", "max diff ms", "max range ms"):
        table.add_column(column)
    for item in result.items:
        kf = item.report
        table.add_row(
            item.name,
            str(kf["frames"]),
            str(kf["keyframes"]),
            "yes" if kf["stationary"] else "",
            f"{kf['path_length_m']:.1f}",
            f"{kf['max_time_diff_us'] / 1000:.1f}",
            f"{kf['max_time_range_us'] / 1000:.1f}",
        )
    console.print(table)
    console.print(f"  -> {result.workspace.stage_dir('keyframes')}")
