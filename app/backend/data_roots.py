"""Server-side folders named in requests (a site's rasters, an export's data set) may only lie inside the
configured data roots (`Settings.data_roots`, CAMA_DATA_ROOTS; default the server's data folder).

A path is resolved (symlinks and `..`) before it is checked, and every refusal reads the same, whether the
folder is missing, unreadable or outside the roots, and names no filesystem detail: an API caller learns nothing
about the server's disk beyond the folders it was given.
"""

import logging
import os
from collections.abc import Sequence
from pathlib import Path

from pydantic import ValidationInfo

from app.backend.errors import InvalidInputError

logger = logging.getLogger(__name__)

ROOTS_CONTEXT = "data_roots"
"""Key of the resolved roots in a pydantic validation context (`data_folder_validator`)."""


def inside(path: Path, roots: Sequence[Path]) -> bool:
    """Whether the resolved `path` is one of `roots` (resolved) or lies below one."""
    return any(path == root or path.is_relative_to(root) for root in roots)


def data_folder(value: str, *, roots: Sequence[Path], field: str) -> Path:
    """The readable folder `value` names, resolved, when it lies inside `roots` (already resolved);
    InvalidInputError naming only `field` otherwise (the same answer for missing, unreadable and outside)."""
    refused = InvalidInputError(
        field, "not a readable folder inside the server's data roots (CAMA_DATA_ROOTS); ask its operator"
    )
    if not value or "\x00" in value:
        raise refused
    try:
        path = Path(value).resolve()
        readable = path.is_dir() and os.access(path, os.R_OK | os.X_OK)
    except (OSError, RuntimeError, ValueError):  # a symlink loop, a name too long
        raise refused from None
    if not (inside(path, roots) and readable):
        logger.info(
            "%s refused: %s (resolved %s) is not a readable folder inside %s", field, value, path, roots
        )
        raise refused
    return path


def data_folder_validator(value: str | None, info: ValidationInfo) -> str | None:
    """A pydantic after-validator for a folder field: checked against the roots given in the validation
    context (`{ROOTS_CONTEXT: roots}`) and replaced by its resolved path; unchecked without a context (a
    stored job's params, already checked when submitted)."""
    roots = (info.context or {}).get(ROOTS_CONTEXT)
    if value is None or roots is None:
        return value
    return str(data_folder(value, roots=roots, field=info.field_name or "path"))
