"""Skeletonisation of binary masks, isolated here so the implementation can be swapped in one place.

scikit-image's `skeletonize` is used when it is installed; otherwise a numpy Zhang-Suen thinning of the
same kind gives one-pixel-wide skeletons (slower, and it may differ from scikit-image by a pixel here and
there).
"""

import logging
from collections.abc import Callable
from typing import Any

import numpy as np

logger = logging.getLogger(__name__)

_skimage_skeletonize: Callable[..., Any] | None
try:
    from skimage.morphology import skeletonize as _skimage_skeletonize
except ImportError:  # pragma: no cover - depends on the environment
    _skimage_skeletonize = None
    logger.warning("scikit-image is not installed: skeletons come from the numpy Zhang-Suen fallback")


def skeletonize(mask: np.ndarray) -> np.ndarray:
    """One-pixel-wide skeleton (bool, same shape) of a 2D binary mask, so a marking becomes a curve."""
    mask = np.asarray(mask)
    if mask.ndim != 2:
        raise ValueError(f"skeletonize needs a 2D mask, got shape {mask.shape}")
    binary = mask.astype(bool)
    if not binary.any():
        return binary
    if _skimage_skeletonize is not None:
        return np.asarray(_skimage_skeletonize(binary), dtype=bool)
    return zhang_suen_thinning(binary)


def zhang_suen_thinning(mask: np.ndarray) -> np.ndarray:
    """Zhang-Suen thinning of a bool mask (the fallback when scikit-image is missing)."""
    image = np.pad(mask.astype(np.uint8), 1)
    while True:
        changed = False
        for step in (0, 1):
            p = _neighbours(image)
            p2, p3, p4, p5, p6, p7, p8, p9 = p
            count = sum(p)
            ring = [p2, p3, p4, p5, p6, p7, p8, p9, p2]
            transitions = sum(
                ((a == 0) & (b == 1)).astype(np.uint8) for a, b in zip(ring, ring[1:], strict=False)
            )
            if step == 0:
                side = (p2 * p4 * p6 == 0) & (p4 * p6 * p8 == 0)
            else:
                side = (p2 * p4 * p8 == 0) & (p2 * p6 * p8 == 0)
            remove = (image[1:-1, 1:-1] == 1) & (count >= 2) & (count <= 6) & (transitions == 1) & side
            if remove.any():
                image[1:-1, 1:-1][remove] = 0
                changed = True
        if not changed:
            return image[1:-1, 1:-1].astype(bool)


def _neighbours(image: np.ndarray) -> list[np.ndarray]:
    """The 8 neighbours P2..P9 (clockwise from north) of every interior pixel of a padded image."""
    h, w = image.shape
    shifts = [(-1, 0), (-1, 1), (0, 1), (1, 1), (1, 0), (1, -1), (0, -1), (-1, -1)]
    return [image[1 + dr : h - 1 + dr, 1 + dc : w - 1 + dc].astype(np.int32) for dr, dc in shifts]
