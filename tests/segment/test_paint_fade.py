"""Extra paint wear for training: markings fade toward the road under them, nothing else moves."""

from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from cama_pipeline.console import EXIT_BAD_INPUT
from cama_pipeline.segment.config import TrainConfig
from cama_pipeline.segment.paint_fade import fade_paint, paint_region
from cama_pipeline.segment.train import augment
from cama_pipeline.semantics import Semantic
from cama_studio.cli import app

ROAD_GREY = 90
PAINT_WHITE = 230


def _road_with_stripe() -> tuple[np.ndarray, np.ndarray]:
    """A grey road with a vertical white lane stripe (columns 20-23) and a vehicle block over part of it."""
    image = np.full((40, 64, 3), ROAD_GREY, np.uint8)
    mask = np.full((40, 64), int(Semantic.ROAD), np.uint8)
    image[:, 20:24] = PAINT_WHITE
    mask[:, 20:24] = int(Semantic.LANE_MARKING)
    image[30:, 40:60] = 20
    mask[30:, 40:60] = int(Semantic.VEHICLE)
    return image, mask


def test_full_fade_leaves_the_road_colour_and_touches_nothing_else() -> None:
    image, mask = _road_with_stripe()
    faded = fade_paint(image, mask, 1.0)
    assert np.abs(faded[:, 20:24].astype(int) - ROAD_GREY).max() <= 2
    outside = paint_region(mask) == 0
    assert (faded[outside] == image[outside]).all()
    assert (faded[30:, 40:60] == 20).all()


def test_half_fade_goes_half_way_and_no_fade_or_no_paint_changes_nothing() -> None:
    image, mask = _road_with_stripe()
    half = fade_paint(image, mask, 0.5)[:, 21].astype(int)
    assert np.abs(half - (ROAD_GREY + PAINT_WHITE) / 2).max() <= 2
    assert (fade_paint(image, mask, 0.0) == image).all()
    bare = np.full_like(mask, int(Semantic.ROAD))
    assert (fade_paint(image, bare, 0.8) == image).all()


def test_bad_fades_and_sizes_are_named() -> None:
    image, mask = _road_with_stripe()
    with pytest.raises(ValueError, match="paint fade"):
        fade_paint(image, mask, 1.5)
    with pytest.raises(ValueError, match="differ in size"):
        fade_paint(image, mask[:10], 0.3)
    with pytest.raises(ValueError, match="paint_fade_max"):
        TrainConfig(paint_fade_max=-0.1)


def test_augment_fades_paint_but_keeps_the_mask() -> None:
    """With extra fade the crops' masks are still exact crops of the site's mask, and some crops' stripes stand
    out from the road far less than others (measured as the stripe's contrast with the road)."""
    image, mask = _road_with_stripe()
    config = TrainConfig(crop_height_px=32, crop_width_px=64, paint_fade_max=1.0)
    rng = np.random.default_rng(5)
    contrasts = []
    for _ in range(24):
        rgb, crop = augment(image, mask, config, rng)
        assert any((c == mask[y : y + 32]).all() for y in range(9) for c in (crop, crop[:, ::-1]))
        stripe = rgb[crop == int(Semantic.LANE_MARKING)].mean()
        road = rgb[crop == int(Semantic.ROAD)].mean()
        contrasts.append(stripe - road)
    assert min(contrasts) < 0.5 * max(contrasts)


def test_train_segmenter_names_a_bad_paint_fade(tmp_path: Path) -> None:
    args = [
        "train-segmenter",
        "--sites",
        str(tmp_path),
        "--out",
        str(tmp_path / "c"),
        "--paint-fade-max",
        "2",
    ]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == EXIT_BAD_INPUT and "paint_fade_max" in result.output, result.output
    assert not (tmp_path / "c").exists()
