"""Kerb steps (`cama_pipeline.surface.steps`): colour moments, the raise decision on hand-made votes, the report."""

import numpy as np
import pytest
import torch

from cama_pipeline.semantics import BEV_CLASSES, Semantic
from cama_pipeline.surface.grid import SurfaceGrid
from cama_pipeline.surface.labels import curb_logits
from cama_pipeline.surface.steps import (
    ColourMoments,
    KerbStepConfig,
    beyond_kerb_line,
    raised_vertices,
    step_summary,
)

ROWS, COLS = 20, 30
GRID = SurfaceGrid((0.0, 0.0), 0.1, ROWS, COLS, np.arange(ROWS * COLS).reshape(ROWS, COLS))
NO_PAINT = np.zeros(ROWS * COLS, bool)


def moments(spread: np.ndarray) -> ColourMoments:
    """Per-vertex moments of two equally weighted views whose colours differ by `spread` (V,) per channel."""
    result = ColourMoments(len(spread), torch.device("cpu"))
    ids = torch.arange(len(spread))
    base = torch.full((len(spread), 3), 0.5)
    offset = torch.as_tensor(spread, dtype=torch.float32)[:, None].expand(-1, 3) / 2
    result.add(ids, base + offset, torch.ones(len(spread)))
    result.add(ids, base - offset, torch.ones(len(spread)))
    return result


def test_colour_moments_give_the_weighted_mean_and_variance() -> None:
    found = ColourMoments(2, torch.device("cpu"))
    found.add(
        torch.tensor([0, 0, 1]),
        torch.tensor([[0.2] * 3, [0.6] * 3, [0.3] * 3]),
        torch.tensor([3.0, 1.0, 2.0]),
    )
    assert torch.allclose(found.mean(), torch.tensor([[0.3] * 3, [0.3] * 3]))
    # vertex 0: values 0.2 (weight 3) and 0.6 (weight 1): variance 0.03 per channel, summed over three
    assert torch.allclose(found.variance(), torch.tensor([0.09, 0.0]), atol=1e-6)


def layout() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Columns 0-14 road, 15-29 sidewalk: road cells agree at road level, sidewalk cells at curb height; the
    two road columns next to the sidewalk (13, 14) are a kerb the road-level vote labelled road."""
    cols = np.tile(np.arange(COLS), ROWS)
    sidewalk = cols >= 15
    kerb_foot = (cols == 13) | (cols == 14)
    at_curb_height = sidewalk | kerb_foot
    road_spread = np.where(at_curb_height, 0.4, 0.02)
    curb_spread = np.where(at_curb_height, 0.02, 0.4)
    return road_spread, curb_spread, sidewalk


def test_off_road_cells_agreeing_at_curb_height_are_raised_and_the_kerb_foot_with_them() -> None:
    road_spread, curb_spread, sidewalk = layout()
    with_foot = KerbStepConfig(kerb_band_m=0.3)
    raised, foot = raised_vertices(
        GRID, moments(road_spread), moments(curb_spread), sidewalk, NO_PAINT, with_foot
    )
    cols = np.tile(np.arange(COLS), ROWS)
    assert raised[sidewalk].all()
    assert foot[(cols == 13) | (cols == 14)].all() and raised[foot].all()
    assert not raised[cols < 13].any() and not foot[sidewalk].any()
    raised, foot = raised_vertices(
        GRID, moments(road_spread), moments(curb_spread), sidewalk, NO_PAINT, KerbStepConfig()
    )
    assert np.array_equal(raised, sidewalk) and not foot.any()  # no foot by default


def test_paint_is_never_the_kerb_foot() -> None:
    """A crossing runs up to the kerb in rows 5-9: its painted cells in the foot's columns stay road (paint lies on
    the road), the foot elsewhere along the kerb is unchanged."""
    road_spread, curb_spread, sidewalk = layout()
    rows, cols = np.repeat(np.arange(ROWS), COLS), np.tile(np.arange(COLS), ROWS)
    crossing = (rows >= 5) & (rows <= 9) & (cols < 15)
    config = KerbStepConfig(kerb_band_m=0.3)
    _, foot = raised_vertices(GRID, moments(road_spread), moments(curb_spread), sidewalk, crossing, config)
    assert not foot[crossing].any()
    assert np.array_equal(foot[~crossing], ((cols == 13) | (cols == 14))[~crossing])


def test_the_foot_is_labelled_curb() -> None:
    logits = curb_logits(4, torch.device("cpu"))
    assert logits.shape == (4, len(BEV_CLASSES))
    assert (logits.argmax(dim=1) == BEV_CLASSES.index(Semantic.CURB)).all()


def test_the_foot_is_a_band_of_one_width_along_the_kerb_despite_noisy_cells() -> None:
    """A fifth of the cells near the kerb read the wrong way (foot cells agreeing at road level, road cells at
    curb height): the foot is still exactly the two kerb columns in every row, the road's edge a straight line."""
    road_spread, curb_spread, sidewalk = layout()
    cols = np.tile(np.arange(COLS), ROWS)
    flipped = (np.random.default_rng(3).random(ROWS * COLS) < 0.2) & (cols >= 9) & (cols <= 14)
    road_spread[flipped], curb_spread[flipped] = curb_spread[flipped], road_spread[flipped]
    config = KerbStepConfig(kerb_band_m=0.5)
    raised, foot = raised_vertices(
        GRID, moments(road_spread), moments(curb_spread), sidewalk, NO_PAINT, config
    )
    assert np.array_equal(foot, (cols == 13) | (cols == 14))
    assert np.array_equal(raised, sidewalk | foot)


def test_the_foot_width_follows_the_kerb_where_it_changes() -> None:
    """Rows 0-9 have a one-cell foot, rows 10-19 a three-cell one; with a short smoothing each half keeps its
    own width away from the change."""
    cols, rows = np.tile(np.arange(COLS), ROWS), np.repeat(np.arange(ROWS), COLS)
    sidewalk = cols >= 15
    kerb_foot = np.where(rows < 10, cols == 14, (cols >= 12) & (cols <= 14))
    at_curb_height = sidewalk | kerb_foot
    road_spread, curb_spread = np.where(at_curb_height, 0.4, 0.02), np.where(at_curb_height, 0.02, 0.4)
    config = KerbStepConfig(kerb_band_m=0.5, foot_smoothing_m=0.1)
    _, foot = raised_vertices(GRID, moments(road_spread), moments(curb_spread), sidewalk, NO_PAINT, config)
    away = (rows < 7) | (rows > 12)
    assert np.array_equal(foot[away], kerb_foot[away])


def test_road_far_from_a_raised_region_is_never_raised() -> None:
    road_spread, curb_spread, sidewalk = layout()
    cols = np.tile(np.arange(COLS), ROWS)
    curb_spread = np.where(cols < 5, 0.0, curb_spread)  # road that happens to agree better at curb height
    road_spread = np.where(cols < 5, 0.4, road_spread)
    with_foot = KerbStepConfig(kerb_band_m=0.3)
    raised, _ = raised_vertices(
        GRID, moments(road_spread), moments(curb_spread), sidewalk, NO_PAINT, with_foot
    )
    assert not raised[cols < 5].any()


def test_small_raised_patches_and_unseen_cells_stay_down() -> None:
    cols, rows = np.tile(np.arange(COLS), ROWS), np.repeat(np.arange(ROWS), COLS)
    off_road = np.ones(ROWS * COLS, bool)
    patch = (rows < 3) & (cols < 3)  # 0.09 m2, under the 0.5 m2 minimum
    road_spread, curb_spread = np.where(patch, 0.4, 0.02), np.where(patch, 0.02, 0.4)
    raised, _ = raised_vertices(
        GRID, moments(road_spread), moments(curb_spread), off_road, NO_PAINT, KerbStepConfig()
    )
    assert not raised.any()
    unseen = ColourMoments(ROWS * COLS, torch.device("cpu"))
    raised, _ = raised_vertices(GRID, unseen, moments(curb_spread), off_road, NO_PAINT, KerbStepConfig())
    assert not raised.any()


def test_step_summary_counts_the_raised_share_of_off_road_cells() -> None:
    semantic = np.array([[int(Semantic.ROAD), int(Semantic.CURB), int(Semantic.BACKGROUND), 255]], np.uint8)
    step = np.array([[0.0, 0.13, 0.0, np.nan]], np.float32)
    assert step_summary(semantic, step, 0.13) == {
        "height_m": 0.13,
        "cells_raised": 1,
        "off_road_share_raised": 0.5,
    }


def test_bad_config_names_the_field() -> None:
    with pytest.raises(ValueError, match="kerb_band_m"):
        KerbStepConfig(kerb_band_m=-1)
    with pytest.raises(ValueError, match="foot_smoothing_m"):
        KerbStepConfig(foot_smoothing_m=-0.5)


def smeared_votes(kerb_col: float, smear_cols: float) -> tuple[np.ndarray, np.ndarray]:
    """(V, 5) class shares of a kerb whose line lies at column `kerb_col` (kerb beyond) as the two votes read it: the road-level vote calls the kerb top road for `smear_cols` columns beyond the line (fading out), the
    curb-height vote calls the road off-road for as many columns before it (fading in), as views from the road do."""
    beyond = np.tile(np.arange(COLS), ROWS) - kerb_col  # > 0: on the kerb, < 0: on the road
    road_level_road = np.clip(1 - beyond / smear_cols, 0, 1)
    curb_height_road = np.clip(-beyond / smear_cols, 0, 1)
    road, curb = BEV_CLASSES.index(Semantic.ROAD), BEV_CLASSES.index(Semantic.CURB)
    road_level, curb_height = np.zeros((len(beyond), 5)), np.zeros((len(beyond), 5))
    road_level[:, road], road_level[:, curb] = road_level_road, 1 - road_level_road
    curb_height[:, road], curb_height[:, curb] = curb_height_road, 1 - curb_height_road
    return road_level, curb_height


def test_the_kerb_line_lies_between_the_two_votes_smeared_edges() -> None:
    # the kerb line at column 14.5: each vote alone puts the road's edge 3 columns off, in opposite directions
    road_level, curb_height = smeared_votes(14.5, 6.0)
    road_labelled = road_level.argmax(axis=1) == BEV_CLASSES.index(Semantic.ROAD)
    cols = np.tile(np.arange(COLS), ROWS)
    assert cols[road_labelled].max() == 17  # the road-level vote labels three kerb columns road
    seen = np.ones(len(cols), bool)
    line = beyond_kerb_line(
        GRID, road_level, curb_height, seen, road_labelled, KerbStepConfig(kerb_line=True)
    )
    assert set(cols[line]) == {15, 16, 17}  # exactly the kerb columns the road-level vote took for road
    assert not line[~road_labelled].any()  # only candidates are ever beyond
    config = KerbStepConfig(kerb_line=True)
    unseen = seen & (cols != 16)
    assert not beyond_kerb_line(GRID, road_level, curb_height, unseen, road_labelled, config)[
        cols == 16
    ].any()
