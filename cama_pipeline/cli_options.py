"""The typer argument and option types that the stage commands share (`cama wigo`, `keyframes`, `sites`, ...),
spelled once so that every command names and documents them alike. Errors and exit codes: `console`."""

from pathlib import Path
from typing import Annotated

import typer

DatasetArg = Annotated[Path, typer.Argument(help="Data set root (nuScenes layout).")]
WorkspaceOpt = Annotated[
    Path | None, typer.Option(help="Workspace folder; default <data set root's parent>/workspace.")
]
ScenesOpt = Annotated[list[str] | None, typer.Option("--scene", help="Only this scene (repeatable).")]
OverwriteOpt = Annotated[bool, typer.Option(help="Recompute even when the outputs are up to date.")]
MasksOpt = Annotated[
    str,
    typer.Option(
        "--masks",
        help="Image masks: auto (the data set's, else the workspace's predicted, else imported), dataset, "
        "predicted (`cama segment`), imported (`cama import-masks`) or a folder laid out like a data set's masks "
        "(cama_pipeline.data.masks).",
    ),
]
