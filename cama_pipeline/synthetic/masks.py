"""Degrade the rendered (perfect) masks the way a real 2D segmentation network errs."""

import cv2
import numpy as np

from cama_pipeline.semantics import INSTANCE_ID_BASE, Semantic
from cama_pipeline.synthetic.config import MaskNoiseConfig


def degrade_masks(
    semantic: np.ndarray, instance: np.ndarray, cfg: MaskNoiseConfig, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """Jitter class boundaries with a smooth random warp and drop some lane-marking instances."""
    semantic, instance = semantic.copy(), instance.copy()
    if cfg.miss_rate > 0:
        markings = np.unique(instance[instance // INSTANCE_ID_BASE == int(Semantic.LANE_MARKING)])
        for value in markings[rng.uniform(size=markings.size) < cfg.miss_rate]:
            missed = instance == value
            semantic[missed] = int(Semantic.ROAD)
            instance[missed] = 0
    if cfg.boundary_jitter_px > 0:
        semantic, instance = _warp_labels(semantic, instance, cfg.boundary_jitter_px, rng)
    return semantic, instance


def _warp_labels(
    semantic: np.ndarray, instance: np.ndarray, amplitude_px: int, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """Resample both label maps through one smooth displacement field of about `amplitude_px`."""
    h, w = semantic.shape
    coarse = rng.uniform(-1, 1, size=(2, max(2, h // 16), max(2, w // 16))).astype(np.float32)
    dx = cv2.resize(coarse[0], (w, h), interpolation=cv2.INTER_CUBIC) * amplitude_px
    dy = cv2.resize(coarse[1], (w, h), interpolation=cv2.INTER_CUBIC) * amplitude_px
    grid_x, grid_y = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    map_x, map_y = grid_x + dx, grid_y + dy
    warped_sem = cv2.remap(semantic, map_x, map_y, cv2.INTER_NEAREST, borderMode=cv2.BORDER_REPLICATE)
    warped_inst = cv2.remap(
        instance.astype(np.float32), map_x, map_y, cv2.INTER_NEAREST, borderMode=cv2.BORDER_REPLICATE
    ).astype(instance.dtype)
    fixed = (semantic == int(Semantic.EGO)) | (semantic == int(Semantic.SKY))
    warped_sem[fixed] = semantic[fixed]
    return warped_sem, warped_inst
