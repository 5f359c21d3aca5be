"""Configurations of the element-mask network and its training, frozen and validated on creation."""

from dataclasses import dataclass

from models.vma.rasters import NUM_SEMANTIC
from models.vma.vectors import CLASSES


@dataclass(frozen=True)
class MaskModelConfig:
    """Architecture and raster geometry of the element-mask network; a checkpoint loads only into its own."""

    resolution_m: float = 0.2
    """Metres per network pixel (site rasters are resampled to it)."""
    base_channels: int = 16
    """Channels of the full-resolution stage; each of the three downsampled stages doubles them (at most 96)."""
    line_width_m: float = 0.6
    """Width of the band a divider or boundary is drawn as in the target masks."""

    def __post_init__(self) -> None:
        if not self.resolution_m > 0 or not self.line_width_m > 0:
            raise ValueError("MaskModelConfig: resolution_m and line_width_m must be > 0")
        if self.base_channels < 4:
            raise ValueError(f"MaskModelConfig.base_channels must be >= 4, got {self.base_channels}")

    @property
    def in_channels(self) -> int:
        """One-hot semantic classes plus RGB (`models.vma.rasters.model_input`)."""
        return NUM_SEMANTIC + 3

    @property
    def out_channels(self) -> int:
        """One mask per vector class, in `models.vma.vectors.CLASSES` order."""
        return len(CLASSES)


@dataclass(frozen=True)
class MaskTrainConfig:
    """How the element-mask network is trained (and fine-tuned on corrections, with fewer steps)."""

    steps: int = 3000
    batch_size: int = 8
    crop_px: int = 128
    """Side of the square training crops (25.6 m at 0.2 m/px)."""
    learning_rate: float = 2e-3
    weight_decay: float = 1e-4
    damaged_copies: int = 4
    """Damaged copies of every training site (`models.vma.degrade`, random strengths) beside the clean one."""
    unobserved_share: float = 0.3
    """Share of crops in which a random region is made unobserved (reconstructions see only what was driven)."""
    appearance_share: float = 0.8
    """Share of crops given another exposure, gamma, contrast and tint (`train.jitter_appearance`)."""
    seed: int = 0
    threads: int = 2
    max_seconds: float = 1e9
    """Time budget: training stops at `steps` or here, whichever comes first (the schedule follows both)."""

    def __post_init__(self) -> None:
        if self.steps < 1 or self.batch_size < 1 or not self.learning_rate > 0:
            raise ValueError("MaskTrainConfig: steps >= 1, batch_size >= 1 and learning_rate > 0 required")
        if self.crop_px < 32 or self.crop_px % 8:
            raise ValueError(f"MaskTrainConfig.crop_px must be a multiple of 8 and >= 32, got {self.crop_px}")
        if self.damaged_copies < 0 or not 0.0 <= self.unobserved_share <= 1.0:
            raise ValueError("MaskTrainConfig: damaged_copies >= 0 and unobserved_share in [0, 1] required")
        if not 0.0 <= self.appearance_share <= 1.0:
            raise ValueError(
                f"MaskTrainConfig.appearance_share must be in [0, 1], got {self.appearance_share}"
            )
        if not self.max_seconds > 0:
            raise ValueError(f"MaskTrainConfig.max_seconds must be > 0, got {self.max_seconds}")
        if self.threads < 1:
            raise ValueError(f"MaskTrainConfig.threads must be >= 1, got {self.threads}")
