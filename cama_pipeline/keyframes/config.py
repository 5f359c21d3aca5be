"""Configuration of multi-view resynchronisation and keyframe selection."""

import math
from dataclasses import asdict, dataclass
from typing import Any


@dataclass(frozen=True)
class KeyframeConfig:
    """Thresholds of the resync (CAMAv2 "Dirty Details" (1)) and of the keyframe choice."""

    reference_channel: str = "CAM_FRONT"
    """Camera whose images define the frames (and the frame time); the channel with most images if absent."""
    max_time_diff_ms: float = 40.0
    """An image joins a frame only if its time is within this of the frame time (the paper's 40 ms)."""
    min_translation_m: float = 2.0
    """A frame becomes a keyframe once the ego moved this far since the last keyframe."""
    min_rotation_deg: float = 3.0
    """... or turned this much since the last keyframe (so turns get denser keyframes)."""
    stationary_extent_m: float = 1.5
    """A clip whose fused positions all stay within this of its first one is stationary: all frames kept."""

    def __post_init__(self) -> None:
        if not isinstance(self.reference_channel, str) or not self.reference_channel:
            raise ValueError(
                f"KeyframeConfig.reference_channel must be a channel name, got {self.reference_channel!r}"
            )
        for name in ("max_time_diff_ms", "min_translation_m", "min_rotation_deg", "stationary_extent_m"):
            value = getattr(self, name)
            if (
                isinstance(value, bool)
                or not isinstance(value, int | float)
                or not math.isfinite(value)
                or value <= 0
            ):
                raise ValueError(f"KeyframeConfig.{name} must be a finite number > 0, got {value!r}")

    def to_json(self) -> dict[str, Any]:
        return asdict(self)
