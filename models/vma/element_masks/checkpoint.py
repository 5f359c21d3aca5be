"""Versions of the element-mask network in a registry, with the data each saw (`models.vma.checkpoint` format).

A version's `checkpoint.json` says `kind: element_masks`, so a registry of the MapTR-style model and one of
this network are never mistaken for each other; saving, promotion, the record of seen sites and the refusal to
be scored on them (`models.vma.checkpoint.ensure_unseen` takes a `MaskCheckpoint` too) are the VMA registry's
own.
"""

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from models.vma.checkpoint import META, CheckpointError, current_version, load_weights
from models.vma.config import config_fingerprint
from models.vma.element_masks.config import MaskModelConfig
from models.vma.element_masks.net import ElementMaskNet

KIND = "element_masks"
"""`checkpoint.json` field `kind` of this network's versions."""


@dataclass(frozen=True)
class MaskCheckpoint:
    """A loaded version: the network (eval mode) and its metadata."""

    model: ElementMaskNet
    meta: dict[str, Any]
    path: Path


def load_mask_checkpoint(path: Path, device: str = "cpu") -> MaskCheckpoint:
    """Load an element-mask version folder (or a registry's promoted one); CheckpointError naming the file when
    it is another kind of checkpoint, unreadable, or its weights do not fit its config."""
    folder = current_version(Path(path))
    meta_path = folder / META
    try:
        meta = json.loads(meta_path.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError) as err:
        raise CheckpointError(f"{meta_path}: unreadable checkpoint metadata: {err!r}") from None
    if meta.get("kind") != KIND:
        raise CheckpointError(
            f"{meta_path}: field 'kind' is {meta.get('kind')!r}, not an {KIND!r} checkpoint"
            + (" (a MapTR-style VMA checkpoint: use proposer 'learned')" if "model_config" in meta else "")
        )
    try:
        config = MaskModelConfig(**meta["model_config"])
    except (KeyError, TypeError, ValueError) as err:
        raise CheckpointError(f"{meta_path}: field 'model_config': {err!r}") from None
    if meta.get("config_fingerprint") != config_fingerprint(config):
        raise CheckpointError(f"{meta_path}: config_fingerprint does not match its model_config")
    return MaskCheckpoint(load_weights(ElementMaskNet(config), folder, device), meta, folder)
