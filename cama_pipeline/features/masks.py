"""Feature masks: where no keypoint may lie (the ego body and vehicles, from the semantic masks, dilated)."""

import cv2
import numpy as np


def blocked_pixels(semantic: np.ndarray, classes: tuple[int, ...], dilation_px: int) -> np.ndarray:
    """(H, W) bool: True on pixels of `classes`, grown by `dilation_px` (an elliptic structuring element)."""
    blocked = np.isin(semantic, classes)
    if dilation_px > 0 and blocked.any():
        size = 2 * dilation_px + 1
        kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (size, size))
        blocked = cv2.dilate(blocked.astype(np.uint8), kernel).astype(bool)
    return np.asarray(blocked)


def keypoints_allowed(keypoints_xy: np.ndarray, blocked: np.ndarray) -> np.ndarray:
    """(N,) bool: keypoints (x, y pixel coordinates, pixel centres at integers) outside blocked pixels."""
    if len(keypoints_xy) == 0:
        return np.zeros(0, dtype=bool)
    height, width = blocked.shape
    cols = np.clip(np.round(keypoints_xy[:, 0]).astype(int), 0, width - 1)
    rows = np.clip(np.round(keypoints_xy[:, 1]).astype(int), 0, height - 1)
    return np.asarray(~blocked[rows, cols])
