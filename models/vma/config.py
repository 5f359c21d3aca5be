"""Configurations of the learned VMA model and its training, frozen and validated on creation."""

import dataclasses
import hashlib
import json
from dataclasses import dataclass
from typing import Any

from models.vma.rasters import NUM_SEMANTIC


@dataclass(frozen=True)
class ModelConfig:
    """Architecture and input geometry of the MapTR-style model; a checkpoint only loads into its own config."""

    resolution_m: float = 0.25
    """Metres per input pixel (site rasters are resampled to it)."""
    patch_px: int = 128
    """Side of the square input patch (32 m at 0.25 m/px)."""
    num_queries: int = 20
    """Instance queries: the most vectors one patch can hold."""
    num_points: int = 10
    """Fixed points per vector."""
    dim: int = 96
    """Feature width of the backbone output and the decoder."""
    decoder_layers: int = 2
    heads: int = 4
    anchored: bool = False
    """Instance queries initialised from the rule-based proposer's candidates (see `models.vma.anchors`);
    free learned queries fill the slots no candidate takes."""

    def __post_init__(self) -> None:
        if not self.resolution_m > 0:
            raise ValueError(f"ModelConfig.resolution_m must be > 0, got {self.resolution_m}")
        if self.patch_px < 32 or self.patch_px % 16:
            raise ValueError(f"ModelConfig.patch_px must be a multiple of 16 and >= 32, got {self.patch_px}")
        if self.num_queries < 1 or self.num_points < 3:
            raise ValueError("ModelConfig: num_queries >= 1 and num_points >= 3 required")
        if self.dim % self.heads or self.decoder_layers < 1:
            raise ValueError("ModelConfig: dim must divide by heads and decoder_layers >= 1")

    @property
    def in_channels(self) -> int:
        """One-hot semantic classes plus RGB."""
        return NUM_SEMANTIC + 3

    @property
    def patch_m(self) -> float:
        """Side of a patch in metres."""
        return self.patch_px * self.resolution_m


ANCHORED_MODEL = ModelConfig(resolution_m=0.4, patch_px=80, num_queries=24, dim=48, anchored=True)
"""The shipped anchored model: 32 m patches at 0.4 m/px, small enough to train on 2 CPU cores in minutes."""


@dataclass(frozen=True)
class TrainConfig:
    """How the model is trained (and fine-tuned, with fewer steps)."""

    steps: int = 2000
    batch_size: int = 8
    learning_rate: float = 1e-3
    weight_decay: float = 1e-4
    procedural_share: float = 0.5
    """Share of each batch drawn from procedural patches (the rest from site patches)."""
    class_weight: float = 2.0
    """Weight of the focal class loss (matching cost and loss)."""
    point_weight: float = 5.0
    """Weight of the L1 point loss (coordinates normalised to the patch)."""
    seed: int = 0
    threads: int = 2
    """torch CPU threads."""
    max_seconds: float = 1e9
    """Time budget: training stops at `steps` or here, whichever comes first (the schedule follows both)."""

    def __post_init__(self) -> None:
        if self.steps < 1 or self.batch_size < 1 or not self.learning_rate > 0:
            raise ValueError("TrainConfig: steps >= 1, batch_size >= 1 and learning_rate > 0 required")
        if not self.max_seconds > 0:
            raise ValueError(f"TrainConfig.max_seconds must be > 0, got {self.max_seconds}")
        if not 0.0 <= self.procedural_share <= 1.0:
            raise ValueError(f"TrainConfig.procedural_share must be in [0, 1], got {self.procedural_share}")


def config_dict(config: Any) -> dict:
    """A dataclass config as a JSON-ready dict."""
    return dataclasses.asdict(config)


_ADDED_FIELDS: dict[str, Any] = {"anchored": False}
"""Fields added after checkpoints were shipped, with their defaults: hashed only when set otherwise, so older
checkpoints keep their fingerprint."""


def config_fingerprint(config: Any) -> str:
    """Hash of a model config (a frozen dataclass): checkpoints record it and refuse to load into another."""
    fields = {k: v for k, v in config_dict(config).items() if k not in _ADDED_FIELDS or v != _ADDED_FIELDS[k]}
    return hashlib.sha256(json.dumps(fields, sort_keys=True).encode()).hexdigest()[:16]
