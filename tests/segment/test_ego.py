"""The ego body from a clip's constant pixels: on made-up frames, and on the tiny site against the generator's mask."""

import numpy as np
import pytest

from cama_pipeline.data import load_dataset
from cama_pipeline.segment.ego import EgoConfig, body_pieces, constant_pixels, estimate_ego_mask
from cama_pipeline.semantics import Semantic
from tests.conftest import GeneratedSite


def made_up_frames(count: int = 10, seed: int = 0) -> tuple[list[np.ndarray], np.ndarray]:
    """Frames of moving texture with a fixed dark body at the bottom and a fixed sky band at the top."""
    rng = np.random.default_rng(seed)
    body = np.zeros((40, 64), bool)
    body[32:, 10:50] = True
    frames = []
    for _ in range(count):
        frame = rng.integers(60, 200, (40, 64)).astype(np.uint8)
        frame[body] = 30
        frame[:8] = 180  # sky: constant, but not touching the bottom
        frames.append(frame)
    return frames, body


def test_constant_pixels_touching_the_bottom_are_the_body() -> None:
    frames, body = made_up_frames()
    config = EgoConfig(min_area_fraction=0.01)
    constant = constant_pixels(frames, config)
    assert constant[:8].all() and constant[body].all()
    assert constant[~body][8 * 64 :].mean() < 0.05
    found = body_pieces(constant, config)
    assert not found[:8].any() and found[body].mean() > 0.98 and not found[~body].any()  # corners rounded


def test_holes_in_the_body_are_filled_and_small_pieces_dropped() -> None:
    constant = np.zeros((40, 64), bool)
    constant[30:, 10:50] = True
    constant[34:36, 20:24] = False  # a changing reflection inside the body
    constant[37:, 58:61] = True  # a small still speck on the bottom edge
    body = body_pieces(constant, EgoConfig(open_px=0, min_area_fraction=0.01))
    assert body[34:36, 20:24].all() and not body[37:, 58:61].any()


def test_config_is_checked() -> None:
    with pytest.raises(ValueError, match="min_frames"):
        EgoConfig(min_frames=2)
    with pytest.raises(ValueError, match="max_frames"):
        EgoConfig(min_frames=8, max_frames=4)
    with pytest.raises(ValueError, match="max_still_fraction"):
        EgoConfig(max_still_fraction=0)


def test_trunk_estimate_matches_the_generators_ego_mask(tiny_site: GeneratedSite) -> None:
    """Moving day clips: CAM_BACK's estimate against the generator's EGO pixels (IoU 0.99-1.00 measured), no ego
    pixel in the other cameras; the standing clip and the night clip give no estimate."""
    dataset = load_dataset(tiny_site.result.dataset_root)
    for scene in dataset.scenes:
        estimates = {channel: estimate_ego_mask(images) for channel, images in scene.images.items()}
        if not scene.description.startswith("Day, moving"):
            assert all(e is None for e in estimates.values()), scene.description
            continue
        truth = scene.images["CAM_BACK"][0].load_semantic() == Semantic.EGO
        trunk = estimates["CAM_BACK"]
        assert trunk is not None and truth.any()
        iou = (trunk & truth).sum() / (trunk | truth).sum()
        assert iou > 0.95, f"{scene.name}: IoU {iou:.3f}"
        for channel, estimate in estimates.items():
            if channel != "CAM_BACK":
                assert estimate is not None and estimate.mean() < 0.002, channel
