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
