"""Configuration of site aggregation."""

import math
from dataclasses import asdict, dataclass
from typing import Any


@dataclass(frozen=True)
class SiteConfig:
    """When scenes share a site, when a scene counts as night, how far a stationary clip may be merged."""

    overlap_radius_m: float = 30.0
    """Two scenes overlap when some pair of their fused positions is closer than this (cameras see ~30 m)."""
    night_keywords: tuple[str, ...] = ("night",)
    """A scene whose description holds one of these words (any case) is night (nuScenes marks it there)."""
    night_brightness: float = 60.0
    """Otherwise a scene is night when the mean 8-bit luma of its sampled key frames is below this."""
    brightness_images: int = 4
    """Key-frame images per scene sampled (evenly over the clip) for the brightness check."""
    stationary_merge_max_m: float = 100.0
    """A stationary clip joins the nearest moving clip within this distance; else it is dropped."""

    def __post_init__(self) -> None:
        for name in ("overlap_radius_m", "night_brightness", "stationary_merge_max_m"):
            value = getattr(self, name)
            if (
                isinstance(value, bool)
                or not isinstance(value, int | float)
                or not math.isfinite(value)
                or value <= 0
            ):
                raise ValueError(f"SiteConfig.{name} must be a finite number > 0, got {value!r}")
        if (
            isinstance(self.brightness_images, bool)
            or not isinstance(self.brightness_images, int)
            or self.brightness_images < 1
        ):
            raise ValueError(
                f"SiteConfig.brightness_images must be an integer >= 1, got {self.brightness_images!r}"
            )
        if not all(isinstance(w, str) and w for w in self.night_keywords):
            raise ValueError(
                f"SiteConfig.night_keywords must be non-empty strings, got {self.night_keywords!r}"
            )

    def to_json(self) -> dict[str, Any]:
        return {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(self).items()}
