"""Reconstruction-like degradation of clean BEV rasters, for benchmarking proposers on imperfect input.

Rasters from the surface reconstruction are not the generator's clean truth: thin markings are missed in
places, class edges wobble, isolated cells are mislabelled and colours are noisy. This applies such damage,
seeded, to a site's rasters so both proposers can be compared on the same imperfect input.
"""

from dataclasses import dataclass, replace

import cv2
import numpy as np

from cama_pipeline.semantics import Semantic
from models.vma.rasters import SiteRasters


@dataclass(frozen=True)
class DegradeConfig:
    """Strength of each kind of damage."""

    marking_dropout: float = 0.15
    """Share of marking pieces (dashes, stripes, line stretches of `piece_m`) relabelled as road."""
    piece_m: float = 3.0
    """Solid lines are cut into pieces of this length for the dropout."""
    speckle: float = 0.005
    """Share of cells given a random class."""
    edge_jitter_px: int = 1
    """Random erosion or dilation radius of each class region."""
    colour_noise: float = 0.04
    """Standard deviation of additive photometric noise (0-1 scale)."""
    seed: int = 0


def degrade_rasters(rasters: SiteRasters, config: DegradeConfig | None = None) -> SiteRasters:
    """A damaged copy of `rasters` (unobserved cells stay unobserved)."""
    config = config or DegradeConfig()
    rng = np.random.default_rng(config.seed)
    semantic = rasters.semantic.copy()
    unobserved = semantic == int(Semantic.UNOBSERVED)
    piece_px = max(1, round(config.piece_m / rasters.resolution_m))
    for label in (int(Semantic.LANE_MARKING), int(Semantic.CROSSWALK)):
        mask = (semantic == label).astype(np.uint8)
        grid = np.zeros_like(mask)
        grid[::piece_px, :] = 1
        grid[:, ::piece_px] = 1
        count, pieces = cv2.connectedComponents(mask & (1 - grid))
        dropped = np.flatnonzero(rng.random(count) < config.marking_dropout)
        semantic[
            np.isin(pieces, dropped[dropped > 0])
            | ((mask > 0) & (grid > 0) & (rng.random(mask.shape) < config.marking_dropout))
        ] = int(Semantic.ROAD)
    if config.edge_jitter_px > 0:
        kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * config.edge_jitter_px + 1,) * 2)
        for label in (int(Semantic.CURB), int(Semantic.LANE_MARKING)):
            mask = (semantic == label).astype(np.uint8)
            if rng.random() < 0.5:
                grown = cv2.dilate(mask, kernel) > 0
                semantic[grown & (semantic == int(Semantic.ROAD)) & (rng.random(mask.shape) < 0.5)] = label
    speckle = rng.random(semantic.shape) < config.speckle
    semantic[speckle] = rng.integers(0, 5, int(speckle.sum()))
    semantic[unobserved] = int(Semantic.UNOBSERVED)
    noise = rng.normal(0.0, config.colour_noise * 255, rasters.photometric.shape)
    photometric = np.clip(rasters.photometric.astype(np.float64) + noise, 0, 255).astype(np.uint8)
    return replace(rasters, semantic=semantic, photometric=photometric)
