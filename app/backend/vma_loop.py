"""The backend's one door to the VMA loop's policy (`models.vma.loop`): pre-accept threshold, when to retrain,
the QA sample.

`models.vma` imports torch (seconds and hundreds of MB), which the server needs only once a loop feature is
used, so this module and `jobs/vma.py` import it inside their functions: `cama serve` starts without it.
"""

import logging
from collections.abc import Collection
from dataclasses import replace
from pathlib import Path

from app.backend.config import Settings

logger = logging.getLogger(__name__)


def preaccept_threshold(registry: Path) -> float | None:
    """The promoted checkpoint's calibrated pre-accept confidence; None when it has none."""
    from models.vma.loop import preaccept_threshold as calibrated

    return calibrated(registry)


def should_retrain(new_corrections: int, retrain_after: int) -> bool:
    """Whether enough new accepted/fixed corrections arrived since the last retrain (0 turns it off)."""
    from models.vma.loop import LoopConfig
    from models.vma.loop import should_retrain as policy

    return policy(new_corrections, LoopConfig(retrain_after_corrections=retrain_after))


def qa_sample(element_ids: Collection[int], share: float, seed: int) -> set[int]:
    """A reproducible sample of `share` of the ids for the lead's QA (at least one when share > 0)."""
    from models.vma.loop import qa_sample as sample

    return sample(element_ids, share, seed)


MASK_REGISTRY = "vma-mask-registry"
MAPTR_REGISTRY = "vma-registry"


def shipped_model_of(settings: Settings) -> str:
    """The shipped network a server's default registry holds: `settings.vma_model`, or for `auto` the element-mask
    network unless the data folder already holds a MapTR-style registry and no mask registry (a server started
    before the default changed keeps the versions its leads trained)."""
    if settings.vma_model != "auto":
        return settings.vma_model
    data_dir = Path(settings.data_dir)
    only_maptr = (data_dir / MAPTR_REGISTRY).is_dir() and not (data_dir / MASK_REGISTRY).is_dir()
    return "maptr" if only_maptr else "masks"


def with_shipped_registry(settings: Settings) -> Settings:
    """`settings` with a VMA registry: the configured one, else `<data_dir>/vma-mask-registry` (the element-mask
    network; or `<data_dir>/vma-registry`, the MapTR-style model, per `shipped_model_of`), seeded on first start
    with a copy of that model as shipped in the package (found from any working directory), so the servers that
    `cama serve` and `cama demo` start can refresh proposals with the learned model and retrain it, and new
    versions land in the server's data folder, never inside the installed package."""
    from models.vma.shipped import SHIPPED_MASK_REGISTRY, seed_registry

    if settings.vma_registry is not None:
        return settings
    model = shipped_model_of(settings)
    if model == "masks":
        registry = seed_registry(Path(settings.data_dir) / MASK_REGISTRY, SHIPPED_MASK_REGISTRY)
    else:
        registry = seed_registry(Path(settings.data_dir) / MAPTR_REGISTRY)
    logger.info("VMA registry %s (seeded from the shipped %s model)", registry, model)
    return replace(settings, vma_registry=registry)
