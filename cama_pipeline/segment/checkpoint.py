"""Segmenter checkpoints: the weights with their network config, what they were trained on and how they score.

A checkpoint is a folder:

    model.pt          float16 state dict of `SegmentationNet`
    checkpoint.json   schema "cama.segmenter/1":
        {"schema", "label": a name for users, "created_at", "code_version",
         "network": NetworkConfig, "classes": {id: name},
         "train": TrainConfig, "epochs", "images", "seconds",
         "training_sites": [SiteIdentity], "held_out_sites": [SiteIdentity],
         "metrics": {"held_out": {"per_class_iou": {name: iou | null}, "mean_iou", "pixel_accuracy", "images"},
                     "loss": [mean training loss per epoch], "cpu_seconds_per_512x288": float},
         "weights_sha256": digest of model.pt (what the segment stage's outputs record)}

It is written staged (`.<name>.partial`, then renamed), so a folder with `checkpoint.json` is complete.

A site (`SiteIdentity`) is named by the generator's manifest: its preset, seed, location, the digest of its
layout config and of its whole config. A checkpoint may not be scored on a site it was trained on: same seed,
same layout or same location (`ensure_unseen`, which the benchmark calls before measuring).
"""

import hashlib
import json
import logging
import pickle
import shutil
from dataclasses import dataclass
from datetime import UTC, datetime
from importlib.resources import files
from pathlib import Path
from typing import Any

import torch

from cama_pipeline.code_version import code_version
from cama_pipeline.io import atomic_write_json
from cama_pipeline.segment.config import NetworkConfig
from cama_pipeline.segment.network import IMAGE_CLASSES, SegmentationNet
from cama_pipeline.site_identity import SiteIdentity, ensure_not_among, site_identity

logger = logging.getLogger(__name__)

SCHEMA = "cama.segmenter/1"
WEIGHTS = "model.pt"
META = "checkpoint.json"
SHIPPED_NAME = "shipped"
"""The checkpoint folder inside the `cama_pipeline.segment` package (package data)."""


class CheckpointError(ValueError):
    """A checkpoint folder that is missing, unreadable or not a segmenter checkpoint; names the file."""


@dataclass(frozen=True)
class Checkpoint:
    """A loaded checkpoint: the network (eval mode, CPU) and its metadata."""

    net: SegmentationNet
    meta: dict[str, Any]
    path: Path

    @property
    def digest(self) -> str:
        """Short digest of the weights file: the stage records it and reruns when it changes."""
        return str(self.meta["weights_sha256"])[:16]

    @property
    def label(self) -> str:
        return str(self.meta.get("label", self.path.name))

    @property
    def training_sites(self) -> tuple[SiteIdentity, ...]:
        return tuple(SiteIdentity.from_json(s) for s in self.meta.get("training_sites", []))


def shipped_checkpoint() -> Path:
    """The checkpoint installed with the package; CheckpointError when the install lacks it."""
    folder = Path(str(files("cama_pipeline.segment") / SHIPPED_NAME))
    if not (folder / META).is_file():
        raise CheckpointError(
            f"{folder}: the installed package carries no segmenter checkpoint ({META} missing); "
            "reinstall cama-studio or pass --checkpoint"
        )
    return folder


def save_checkpoint(folder: Path, net: SegmentationNet, meta: dict[str, Any]) -> Path:
    """Write `net` and `meta` (label, train config, sites, metrics ...) as the checkpoint folder `folder`,
    replacing one that is there; the network config, classes, time, code version and weights digest are added."""
    folder = Path(folder)
    staging = folder.with_name(f".{folder.name}.partial")
    shutil.rmtree(staging, ignore_errors=True)
    staging.mkdir(parents=True)
    state = {k: v.half() if v.is_floating_point() else v for k, v in net.state_dict().items()}
    torch.save(state, staging / WEIGHTS)
    full = {
        "schema": SCHEMA,
        "label": meta.get("label", folder.name),
        "created_at": datetime.now(UTC).isoformat(timespec="seconds"),
        "code_version": code_version("cama_pipeline.segment"),
        "network": net.config.to_json(),
        "classes": {str(int(c)): c.name.lower() for c in IMAGE_CLASSES},
        **{k: v for k, v in meta.items() if k != "label"},
        "weights_sha256": hashlib.sha256((staging / WEIGHTS).read_bytes()).hexdigest(),
    }
    atomic_write_json(staging / META, full, indent=2)
    if folder.exists():
        shutil.rmtree(folder)
    staging.rename(folder)
    logger.info("saved segmenter checkpoint %s", folder)
    return folder


def read_meta(folder: Path) -> dict[str, Any]:
    """The checked `checkpoint.json` of a checkpoint folder."""
    path = Path(folder) / META
    if not path.is_file():
        raise CheckpointError(f"{path}: not found; {folder} is not a segmenter checkpoint")
    try:
        meta = json.loads(path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as err:
        raise CheckpointError(f"{path}: not valid JSON ({err})") from None
    if not isinstance(meta, dict) or meta.get("schema") != SCHEMA:
        found = meta.get("schema") if isinstance(meta, dict) else type(meta).__name__
        raise CheckpointError(f"{path}: field 'schema' must be {SCHEMA!r}, got {found!r}")
    for name in ("network", "weights_sha256", "training_sites"):
        if name not in meta:
            raise CheckpointError(f"{path}: field {name!r} missing")
    return meta


def load_checkpoint(folder: Path | None = None) -> Checkpoint:
    """Load a checkpoint folder (None: the shipped one); CheckpointError naming the file when it does not load."""
    folder = shipped_checkpoint() if folder is None else Path(folder)
    meta = read_meta(folder)
    try:
        config = NetworkConfig.from_json(meta["network"])
    except ValueError as err:
        raise CheckpointError(f"{folder / META}: field 'network': {err}") from None
    net = SegmentationNet(config)
    weights = folder / WEIGHTS
    try:
        state = torch.load(weights, map_location="cpu", weights_only=True)
        net.load_state_dict({k: v.float() if v.is_floating_point() else v for k, v in state.items()})
    except (OSError, RuntimeError, EOFError, pickle.UnpicklingError) as err:
        raise CheckpointError(f"{weights}: cannot load the weights ({err})") from None
    return Checkpoint(net.eval(), meta, folder)


def ensure_unseen(checkpoint: Checkpoint, site: Path) -> SiteIdentity:
    """The identity of `site` when `checkpoint` never trained on it; SeenSiteError naming the site and the
    training site it shares a seed, layout or location with (scores on a seen site would flatter it)."""
    return ensure_not_among(
        site_identity(site), checkpoint.training_sites, f"checkpoint {checkpoint.label} ({checkpoint.path})"
    )
