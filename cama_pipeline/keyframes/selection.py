"""Keyframe choice by the ego's relative motion: a new keyframe once the ego moved or turned enough since
the last one (so turns, where the view changes fastest, get denser keyframes); stationary clips keep all."""

import math

import numpy as np

from cama_pipeline.keyframes.config import KeyframeConfig


def is_stationary(translation: np.ndarray, config: KeyframeConfig) -> bool:
    """Whether every position stays within `stationary_extent_m` of the first one."""
    if len(translation) == 0:
        return True
    return bool(np.linalg.norm(translation - translation[0], axis=1).max() < config.stationary_extent_m)


def path_length_m(translation: np.ndarray) -> float:
    """Length of the polyline through the positions."""
    return float(np.linalg.norm(np.diff(translation, axis=0), axis=1).sum()) if len(translation) > 1 else 0.0


def rotation_angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    """Angle of the rotation between two rotation matrices, degrees."""
    cos = (np.trace(a.T @ b) - 1.0) / 2.0
    return math.degrees(math.acos(float(np.clip(cos, -1.0, 1.0))))


def select_keyframes(
    rotation: np.ndarray, translation: np.ndarray, config: KeyframeConfig, *, stationary: bool
) -> list[str]:
    """Per frame the reason it is a keyframe ("first", "translation", "rotation", "last", "stationary"),
    or "" when it is not. `rotation` (N, 3, 3) and `translation` (N, 3) are the frames' global_from_ego."""
    n = len(translation)
    if stationary:
        return ["stationary"] * n
    reasons = [""] * n
    last = 0
    for i in range(n):
        if i == 0:
            reasons[i] = "first"
            continue
        if np.linalg.norm(translation[i] - translation[last]) >= config.min_translation_m:
            reasons[i] = "translation"
        elif rotation_angle_deg(rotation[last], rotation[i]) >= config.min_rotation_deg:
            reasons[i] = "rotation"
        if reasons[i]:
            last = i
    if n > 1 and not reasons[-1]:
        reasons[-1] = "last"
    return reasons
