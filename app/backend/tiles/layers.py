"""BEV layers (`cama_pipeline.bev`) turned into display colours (BGRA, OpenCV's order; PNGs read back as RGBA)
plus their legends.

Palette of the semantic layer (RGBA): background grey (128, 128, 128, 90), road dark slate (60, 64, 72, 255),
curb orange (255, 140, 0, 255), lane marking white (255, 255, 255, 255), crosswalk yellow (255, 220, 0, 255);
unobserved (255) and any other id transparent. Elevation uses viridis over the 2nd-98th percentile of observed
cells (NaN transparent); observation count uses viridis on log(1 + count) up to the maximum count (0 transparent).
"""

import logging
from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

import cv2
import numpy as np
from pydantic import BaseModel, ConfigDict

from cama_pipeline.bev import LAYER_NAMES, LayerName
from cama_pipeline.semantics import BEV_CLASSES, Semantic

logger = logging.getLogger(__name__)

SEMANTIC_PALETTE_RGBA: dict[int, tuple[int, int, int, int]] = {
    int(Semantic.BACKGROUND): (128, 128, 128, 90),
    int(Semantic.ROAD): (60, 64, 72, 255),
    int(Semantic.CURB): (255, 140, 0, 255),
    int(Semantic.LANE_MARKING): (255, 255, 255, 255),
    int(Semantic.CROSSWALK): (255, 220, 0, 255),
}
COLORMAP_NAME = "viridis"
_COLORMAP = cv2.COLORMAP_VIRIDIS
_MAX_SAMPLES = 4_000_000
Resampling = Literal["area", "nearest"]


class LegendEntry(BaseModel):
    """One class of a categorical legend."""

    model_config = ConfigDict(frozen=True)

    id: int
    name: str
    rgba: tuple[int, int, int, int]


class Legend(BaseModel):
    """What a layer's colours mean, for the editor to draw a key."""

    model_config = ConfigDict(frozen=True)

    kind: Literal["categorical", "continuous", "image"]
    colormap: str | None = None
    scale: Literal["linear", "log"] | None = None
    min: float | None = None
    max: float | None = None
    unit: str | None = None
    entries: tuple[LegendEntry, ...] = ()


@dataclass(frozen=True)
class LayerStyle:
    """How one layer is coloured (`render`: raster window -> BGRA uint8) and downsampled."""

    name: LayerName
    legend: Legend
    render: Callable[[np.ndarray], np.ndarray]
    resampling: Resampling


def _palette_lut() -> np.ndarray:
    """256 x 4 BGRA lookup table of the semantic palette; unknown ids transparent."""
    lut = np.zeros((256, 4), dtype=np.uint8)
    for class_id, (r, g, b, a) in SEMANTIC_PALETTE_RGBA.items():
        lut[class_id] = (b, g, r, a)
    return lut


_SEMANTIC_LUT = _palette_lut()


def semantic_bgra(ids: np.ndarray) -> np.ndarray:
    """Class ids (uint8) -> BGRA through the fixed palette; unobserved transparent."""
    return _SEMANTIC_LUT[np.asarray(ids, dtype=np.uint8)]


def photometric_bgra(rgb: np.ndarray) -> np.ndarray:
    """RGB photometric raster -> opaque BGRA, colours as they are."""
    return cv2.cvtColor(np.ascontiguousarray(rgb), cv2.COLOR_RGB2BGRA)


def _colormap_bgra(unit: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Values in [0, 1] -> colour-mapped BGRA; cells not `valid` transparent (all channels 0)."""
    levels = np.clip(np.nan_to_num(unit, nan=0.0) * 255.0 + 0.5, 0, 255).astype(np.uint8)
    bgra = cv2.cvtColor(cv2.applyColorMap(levels, _COLORMAP), cv2.COLOR_BGR2BGRA)
    bgra[~valid] = 0
    return bgra


def elevation_bgra(elevation: np.ndarray, low_m: float, high_m: float) -> np.ndarray:
    """Elevation (m) -> colour map over [low_m, high_m] (clipped); NaN transparent."""
    values = np.asarray(elevation, dtype=np.float32)
    span = high_m - low_m if high_m > low_m else 1.0
    return _colormap_bgra((values - low_m) / span, np.isfinite(values))


def count_bgra(counts: np.ndarray, max_count: float) -> np.ndarray:
    """Observation counts -> colour map of log(1 + n) / log(1 + max_count); 0 transparent."""
    values = np.asarray(counts, dtype=np.float32)
    return _colormap_bgra(np.log1p(values) / np.log1p(max(max_count, 1.0)), values > 0)


def robust_range(
    values: np.ndarray, low_pct: float = 2.0, high_pct: float = 98.0
) -> tuple[float, float] | None:
    """Percentile range of the finite values (on a strided view of big rasters, so no giant copy); None if none."""
    stride = max(1, int(np.ceil(np.sqrt(values.size / _MAX_SAMPLES))))
    sample = np.asarray(values[::stride, ::stride], dtype=np.float64)
    finite = sample[np.isfinite(sample)]
    if finite.size == 0:
        return None
    low, high = np.percentile(finite, [low_pct, high_pct])
    return float(low), float(high)


def _semantic_legend() -> Legend:
    """Categorical legend listing the palette."""
    entries = tuple(
        LegendEntry(id=int(c), name=c.name.lower(), rgba=SEMANTIC_PALETTE_RGBA[int(c)]) for c in BEV_CLASSES
    )
    return Legend(kind="categorical", entries=entries)


def layer_style(name: LayerName, raster: np.ndarray) -> LayerStyle:
    """The style of layer `name`, with colour ranges computed once over the whole raster."""
    if name == "semantic":
        return LayerStyle(name, _semantic_legend(), semantic_bgra, "nearest")
    if name == "photometric":
        return LayerStyle(name, Legend(kind="image"), photometric_bgra, "area")
    if name == "elevation":
        low, high = robust_range(raster) or (0.0, 0.0)
        legend = Legend(
            kind="continuous", colormap=COLORMAP_NAME, scale="linear", min=low, max=high, unit="m"
        )
        return LayerStyle(name, legend, lambda window: elevation_bgra(window, low, high), "area")
    if name == "observation_count":
        max_count = float(np.max(raster)) if raster.size else 0.0
        legend = Legend(kind="continuous", colormap=COLORMAP_NAME, scale="log", min=1.0, max=max_count)
        return LayerStyle(name, legend, lambda window: count_bgra(window, max_count), "area")
    raise ValueError(f"unknown raster layer {name!r}; known: {', '.join(LAYER_NAMES)}")


def check_layer(name: LayerName, raster: np.ndarray, shape: tuple[int, int]) -> None:
    """ValueError naming the layer when the raster's shape or dtype is not what the layer needs."""
    expected_ndim = 3 if name == "photometric" else 2
    if raster.ndim != expected_ndim or raster.shape[:2] != shape:
        raise ValueError(
            f"layer {name}: raster shape {raster.shape} does not match georeference (h, w) {shape}"
        )
    if name == "photometric" and (raster.shape[2] != 3 or raster.dtype != np.uint8):
        raise ValueError(f"layer photometric: expected uint8 RGB, got {raster.dtype} x {raster.shape[2]}")
    if name == "semantic" and raster.dtype != np.uint8:
        raise ValueError(f"layer semantic: expected uint8 class ids, got {raster.dtype}")
