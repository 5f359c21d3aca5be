"""Configurations of the segmentation network, its training and the segment stage: frozen, validated on creation.

The network's config travels inside every checkpoint (a checkpoint loads only into the architecture it was
trained with); the training config is recorded beside it; the stage config says which checkpoint runs and how.
"""

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from cama_pipeline.segment.ego_clip import EgoClipConfig

DeviceName = Literal["auto", "cpu", "cuda"]
DEVICES: tuple[str, ...] = ("auto", "cpu", "cuda")

MEASUREMENT_SEEDS = range(9000, 10000)
"""Seeds of the randomised generator sites kept for measuring the segmenter (`bench/segment.py` draws its
held-out sites from here): `cama train-segmenter` refuses a site of one of these seeds."""
MEASUREMENT_PRESET_SEED = 7
"""The named presets (tiny, default, large) at this, their default seed, are the sites the tests, the demo and
the whole-path benchmarks measure on: `cama train-segmenter` refuses them too."""


def _positive_int(owner: str, name: str, value: object) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise ValueError(f"{owner}.{name} must be an integer >= 1, got {value!r}")


def _non_negative_int(owner: str, name: str, value: object) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        raise ValueError(f"{owner}.{name} must be an integer >= 0, got {value!r}")


def _positive_float(owner: str, name: str, value: object) -> None:
    if (
        isinstance(value, bool)
        or not isinstance(value, int | float)
        or not math.isfinite(value)
        or value <= 0
    ):
        raise ValueError(f"{owner}.{name} must be a finite number > 0, got {value!r}")


@dataclass(frozen=True)
class NetworkConfig:
    """Architecture and input geometry of the segmentation network (a compact U-Net)."""

    widths: tuple[int, ...] = (16, 32, 64, 128, 192)
    """Feature channels at strides 2, 4, 8, 16, 32 of the encoder; the decoder mirrors them."""
    input_width_px: int = 512
    """Images are resized to this width (aspect kept) before the network and its output back to the image's
    size, so a 1600x900 image and a 256x144 one are seen at the scale the network was trained at."""
    full_resolution_width: int = 12
    """Channels of the refinement at the input's own resolution (stride 1), which corrects the stride-2 logits
    pixel by pixel; 0: none (the stride-2 logits are upsampled as they are, as in checkpoints before it). A lane
    marking one or two pixels wide cannot be drawn from stride-2 logits: even the true masks, average-pooled to
    stride 2 and upsampled, give lane marking an IoU of 0.73 and curb 0.71 on site 9001 (`bench/segment.py`,
    `resolution_ceiling`)."""

    def __post_init__(self) -> None:
        if len(self.widths) != 5:
            raise ValueError(f"NetworkConfig.widths must have 5 entries (strides 2..32), got {self.widths!r}")
        for i, width in enumerate(self.widths):
            _positive_int("NetworkConfig", f"widths[{i}]", width)
        _positive_int("NetworkConfig", "input_width_px", self.input_width_px)
        _non_negative_int("NetworkConfig", "full_resolution_width", self.full_resolution_width)
        if self.input_width_px % 32:
            raise ValueError(
                f"NetworkConfig.input_width_px must be a multiple of 32, got {self.input_width_px}"
            )

    def to_json(self) -> dict[str, Any]:
        return {
            "widths": list(self.widths),
            "input_width_px": self.input_width_px,
            "full_resolution_width": self.full_resolution_width,
        }

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> "NetworkConfig":
        """The config of a checkpoint's JSON (one without `full_resolution_width` predates the refinement: 0);
        ValueError naming the field when it does not fit."""
        try:
            return cls(
                widths=tuple(data["widths"]),
                input_width_px=data["input_width_px"],
                full_resolution_width=data.get("full_resolution_width", 0),
            )
        except (KeyError, TypeError) as err:
            raise ValueError(f"network config {data!r} lacks or mistypes a field ({err})") from None


@dataclass(frozen=True)
class TrainConfig:
    """How `cama train-segmenter` trains: crops, schedule, loss weights, augmentation strength."""

    epochs: int = 12
    """Passes over the training images."""
    batch_size: int = 8
    crop_height_px: int = 192
    """Training crops are taken from images rescaled to the network's input width (height and width below)."""
    crop_width_px: int = 320
    learning_rate: float = 3e-3
    """Peak AdamW learning rate (one-cycle schedule)."""
    weight_decay: float = 1e-4
    scale_range: tuple[float, float] = (1.0, 1.0)
    """Random rescale (low, high) of each training image before its crop. (1, 1) keeps the images' own scale, so
    no mask is resampled; the network sees every image `input_width_px` wide. A rescale resamples each class's
    share like the image (`train.resize_labels`). The checkpoints trained with (0.7, 1.3) had their masks
    resampled with nearest neighbour instead, which moved thin classes' edges against the image by up to half a
    pixel per crop (9001's lane-marking IoU 0.62 instead of 0.78; README, "Training at the images' own scale").
    With the share resampling the rescale still gains nothing (README, "The rescale again"), so (1, 1) stays the
    default."""
    paint_fade_max: float = 0.0
    """Extra paint wear: half the training crops have their markings faded toward the surface under them by a
    share drawn uniformly in [0, paint_fade_max] (`segment.paint_fade`), so that heavily faded paint, which few
    randomised sites draw, is seen often. 0: none."""
    max_class_weight: float = 6.0
    """Cross-entropy class weights are inverse square-root frequencies, capped at this."""
    images_per_epoch: int | None = None
    """Crops per epoch (a time budget on a big training set); None: one per training image."""
    seed: int = 0
    threads: int = 2
    """torch CPU threads (the machine is shared)."""
    loader_workers: int = 0
    """Processes that make the augmented crops beside the training loop, each drawing its own from the seed and
    its worker id (a GPU trains faster than one CPU core augments). 0: the loop makes them itself, as every
    checkpoint trained on the CPU did; a run repeats exactly for a given seed and worker count."""
    time_budget_s: float | None = None
    """Train for about this many seconds instead of `epochs` passes: the first steps measure the speed and the
    one-cycle schedule runs over the steps the rest holds. The checkpoint records the passes it made. None:
    `epochs` passes."""

    def __post_init__(self) -> None:
        for name in ("epochs", "batch_size", "crop_height_px", "crop_width_px", "threads"):
            _positive_int("TrainConfig", name, getattr(self, name))
        for name in ("learning_rate", "max_class_weight"):
            _positive_float("TrainConfig", name, getattr(self, name))
        if isinstance(self.weight_decay, bool) or not self.weight_decay >= 0:
            raise ValueError(f"TrainConfig.weight_decay must be >= 0, got {self.weight_decay!r}")
        if self.crop_height_px % 32 or self.crop_width_px % 32:
            raise ValueError("TrainConfig: crop_height_px and crop_width_px must be multiples of 32")
        if isinstance(self.paint_fade_max, bool) or not 0.0 <= self.paint_fade_max <= 1.0:
            raise ValueError(f"TrainConfig.paint_fade_max must be in [0, 1], got {self.paint_fade_max!r}")
        low, high = self.scale_range
        if not 0 < low <= high:
            raise ValueError(f"TrainConfig.scale_range must be 0 < low <= high, got {self.scale_range!r}")
        if self.images_per_epoch is not None:
            _positive_int("TrainConfig", "images_per_epoch", self.images_per_epoch)
        _non_negative_int("TrainConfig", "loader_workers", self.loader_workers)
        if self.time_budget_s is not None:
            _positive_float("TrainConfig", "time_budget_s", self.time_budget_s)

    def to_json(self) -> dict[str, Any]:
        out = dataclasses.asdict(self)
        out["scale_range"] = list(self.scale_range)
        return out


@dataclass(frozen=True)
class SegmentConfig:
    """What `cama segment` runs: which checkpoint, on what device, in what batches."""

    checkpoint: Path | None = None
    """A checkpoint folder (`model.pt` + `checkpoint.json`); None: the one shipped with the package."""
    batch_size: int = 8
    """Images per network call."""
    device: DeviceName = "auto"
    """`auto`: CUDA when present, else the CPU."""
    threads_per_worker: int = 1
    """torch CPU threads of each worker process."""
    flip_average: bool = True
    """Average the class probabilities of each image and its mirror image (`SegmentationNet.predict`): 0.005-0.02
    more IoU on the thin classes for twice the network's cost, which the inference copy's folded batch norms and
    channels-last weights keep under the issue's 0.15 s per 512x288 image on one core (README, "Mirror averaging"
    and "Segmenting faster"); off for a team that wants the network's time halved."""
    ego_clip: EgoClipConfig = field(default_factory=EgoClipConfig)
    """How each camera's ego body is made one through its clips after the network ran (`segment.ego_clip`)."""

    def __post_init__(self) -> None:
        _positive_int("SegmentConfig", "batch_size", self.batch_size)
        _positive_int("SegmentConfig", "threads_per_worker", self.threads_per_worker)
        if not isinstance(self.flip_average, bool):
            raise ValueError(f"SegmentConfig.flip_average must be true or false, got {self.flip_average!r}")
        if self.device not in DEVICES:
            raise ValueError(f"SegmentConfig.device must be one of {', '.join(DEVICES)}, got {self.device!r}")
        if self.checkpoint is not None:
            object.__setattr__(self, "checkpoint", Path(self.checkpoint))

    def to_json(self) -> dict[str, Any]:
        return {
            "checkpoint": None if self.checkpoint is None else str(self.checkpoint),
            "batch_size": self.batch_size,
            "device": self.device,
            "threads_per_worker": self.threads_per_worker,
            "flip_average": self.flip_average,
            "ego_clip": self.ego_clip.to_json(),
        }
