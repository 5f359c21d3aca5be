"""The VMA checkpoints shipped inside the package, found from any working directory.

The registry `models/vma/checkpoints/` travels as package data and is located through `importlib.resources`, so
`cama run`, `cama propose` and the backend find it wherever they are started. It is read-only: a server that
retrains gets its own registry (`seed_registry`), a copy of the shipped one in its data folder, so new versions
never land inside the installed package.
"""

import logging
import shutil
from importlib.resources import files
from pathlib import Path

from models.vma.checkpoint import CURRENT, CheckpointError, current_version

logger = logging.getLogger(__name__)

SHIPPED_REGISTRY_NAME = "checkpoints"
"""The registry folder inside the `models.vma` package."""
SHIPPED_MASK_REGISTRY = ("element_masks", "checkpoints")
"""The element-mask network's registry inside the `models.vma` package."""


def shipped_registry(*parts: str) -> Path:
    """The registry of checkpoints installed with the package (the MapTR-style model's, or the one under `parts`,
    e.g. `SHIPPED_MASK_REGISTRY`); CheckpointError when the install lacks it."""
    resource = files("models.vma").joinpath(*(parts or (SHIPPED_REGISTRY_NAME,)))
    registry = Path(str(resource))
    if not (registry / CURRENT).is_file():
        raise CheckpointError(
            f"{registry}: the installed package carries no VMA checkpoint registry ({CURRENT} missing); "
            "reinstall cama-studio or pass --checkpoint"
        )
    return registry


def resolve_checkpoint(checkpoint: Path | None, shipped: tuple[str, ...] = ()) -> Path:
    """The checkpoint folder to load: the given registry or version folder, else the promoted version of the
    shipped registry (`shipped`: its parts, as `shipped_registry` takes them). The result is a version folder, so
    callers can say exactly which weights they use."""
    return current_version(shipped_registry(*shipped) if checkpoint is None else Path(checkpoint))


def checkpoint_label(version: Path) -> str:
    """How a checkpoint version folder is named to users: its version, whether it is the shipped model, and
    where it is, e.g. `v0003 (shipped with the package: /.../models/vma/checkpoints/v0003)`."""
    version = Path(version).resolve()
    shipped = False
    for parts in ((), SHIPPED_MASK_REGISTRY):
        try:
            shipped = shipped or version.parent == shipped_registry(*parts).resolve()
        except CheckpointError:
            pass
    return f"{version.name} ({'shipped with the package: ' if shipped else ''}{version})"


def seed_registry(registry: Path, shipped: tuple[str, ...] = ()) -> Path:
    """A writable registry at `registry`: kept as it is when it already has a promoted version, else made as a
    copy of the shipped registry (`shipped`: its parts, as `shipped_registry` takes them; staged beside it, then
    renamed, so an interruption leaves no half copy)."""
    registry = Path(registry)
    if (registry / CURRENT).is_file():
        return registry
    if registry.exists() and any(registry.iterdir()):
        raise CheckpointError(f"{registry}: not empty and not a VMA registry ({CURRENT} missing)")
    source = shipped_registry(*shipped)
    registry.parent.mkdir(parents=True, exist_ok=True)
    staging = registry.with_name(f".{registry.name}.partial")
    shutil.rmtree(staging, ignore_errors=True)
    shutil.copytree(source, staging, ignore=shutil.ignore_patterns(".*", "__pycache__"))
    if registry.exists():
        registry.rmdir()
    staging.rename(registry)
    logger.info("VMA registry %s seeded from the shipped checkpoints (%s)", registry, source)
    return registry
