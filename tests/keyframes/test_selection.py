"""Keyframe choice: more keyframes in turns than on straight roads, all frames of stationary clips."""

import numpy as np
import pytest

from cama_pipeline.keyframes import KeyframeConfig, is_stationary, select_keyframes
from cama_pipeline.synthetic.motion import rot_z


def trajectory(yaw_rate_rad_s: float, seconds: float = 6.0, speed_mps: float = 8.0, hz: float = 12.0):
    """Frames at `hz` of a drive at constant speed and yaw rate (0: straight)."""
    t = np.arange(0.0, seconds, 1.0 / hz)
    yaw = yaw_rate_rad_s * t
    step = speed_mps / hz * np.stack([np.cos(yaw), np.sin(yaw), np.zeros_like(yaw)], axis=1)
    return rot_z(yaw), np.cumsum(step, axis=0)


def count(reasons: list[str]) -> int:
    return sum(bool(r) for r in reasons)


def test_turns_get_more_keyframes_than_straight_roads() -> None:
    config = KeyframeConfig()
    straight = select_keyframes(*trajectory(0.0), config, stationary=False)
    turn = select_keyframes(*trajectory(8.0 / 20.0), config, stationary=False)  # 20 m radius
    assert count(turn) > 1.3 * count(straight)
    assert "rotation" in turn and "rotation" not in straight
    assert straight[0] == "first" and straight[-1] in ("last", "translation")


def test_keyframes_are_spaced_by_the_translation_threshold() -> None:
    R, t = trajectory(0.0)
    reasons = select_keyframes(R, t, KeyframeConfig(min_translation_m=4.0), stationary=False)
    chosen = t[[i for i, r in enumerate(reasons) if r in ("first", "translation")]]
    gaps = np.linalg.norm(np.diff(chosen, axis=0), axis=1)
    assert np.all(gaps >= 4.0) and np.all(gaps < 4.0 + 8.0 / 12.0 + 1e-9)


def test_stationary_clip_keeps_every_frame() -> None:
    R, t = trajectory(0.0, speed_mps=0.0)
    assert is_stationary(t, KeyframeConfig())
    assert select_keyframes(R, t, KeyframeConfig(), stationary=True) == ["stationary"] * len(t)
    assert not is_stationary(trajectory(0.0)[1], KeyframeConfig())


def test_one_frame_is_a_keyframe() -> None:
    R, t = trajectory(0.0, seconds=0.05)
    assert select_keyframes(R, t, KeyframeConfig(), stationary=False) == ["first"]


@pytest.mark.parametrize("field", ["max_time_diff_ms", "min_translation_m", "min_rotation_deg"])
def test_config_rejects_non_positive_values(field: str) -> None:
    with pytest.raises(ValueError, match=field):
        KeyframeConfig(**{field: 0.0})
