"""The MapTR-style model and loss: equivalent orderings, matching, a few training steps, patches and inference."""

from pathlib import Path

import numpy as np
import pytest
import torch

from models.vma.config import ModelConfig, TrainConfig
from models.vma.infer import InferenceConfig, predict_site
from models.vma.matching import equivalent_orderings, match_and_loss, point_costs, stack_orderings
from models.vma.model import VmaNet
from models.vma.patches import procedural_sample, random_site_sample, site_grid
from models.vma.rasters import load_site_rasters, vector_map_of
from models.vma.train import fit, learning_rate_at, mixed_sampler
from models.vma.vectors import read_vectors

TINY = ModelConfig(patch_px=64, num_queries=8, num_points=6, dim=32, decoder_layers=1, heads=2)


def test_orderings_of_lines_and_rings() -> None:
    line = torch.tensor([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]])
    assert equivalent_orderings(line, closed=False).shape == (2, 3, 2)
    ring = torch.tensor([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0], [0.0, 0.0]])
    options = equivalent_orderings(ring, closed=True)
    assert options.shape == (8, 5, 2)  # 4 start points x 2 directions
    assert torch.equal(options[:, 0], options[:, -1]), "every ordering stays closed"


def test_point_cost_ignores_direction_and_start() -> None:
    labels = torch.tensor([0, 1])  # a divider and a crossing ring
    line = torch.tensor([[0.1, 0.1], [0.2, 0.1], [0.3, 0.1], [0.4, 0.1], [0.5, 0.1]])
    ring = torch.tensor([[0.5, 0.5], [0.7, 0.5], [0.7, 0.7], [0.5, 0.7], [0.5, 0.5]])
    orderings = stack_orderings(labels, torch.stack([line, ring]))
    shifted = torch.cat([torch.roll(ring[:-1], 2, dims=0), torch.roll(ring[:-1], 2, dims=0)[:1]])
    cost, _ = point_costs(torch.stack([line.flip(0), shifted.flip(0)]), orderings)
    assert cost[0, 0] == pytest.approx(0.0) and cost[1, 1] == pytest.approx(0.0)
    assert cost[0, 1] > 0.1


def test_loss_is_zero_for_a_perfect_prediction_and_matches_one_to_one() -> None:
    targets = [torch.tensor([[[0.1, 0.1], [0.5, 0.1], [0.9, 0.1]]])]
    points = torch.full((1, 4, 3, 2), 0.5)
    points[0, 2] = targets[0][0].flip(0)
    logits = torch.full((1, 4, 3), -20.0)
    logits[0, 2, 0] = 20.0
    loss, parts = match_and_loss(logits, [points], [torch.tensor([0])], targets, 2.0, 5.0)
    assert parts["matched"] == 1 and loss.item() == pytest.approx(0.0, abs=1e-6)
    logits[0, 2, 0] = -20.0
    worse, _ = match_and_loss(logits, [points], [torch.tensor([0])], targets, 2.0, 5.0)
    assert worse.item() > 1.0


def test_a_few_steps_lower_the_loss_on_one_repeated_batch() -> None:
    rng = np.random.default_rng(0)
    fixed = [procedural_sample(TINY, rng) for _ in range(2)]
    model = VmaNet(TINY)
    losses = fit(
        model, lambda r: fixed[int(r.integers(2))], TrainConfig(steps=30, batch_size=2), show_progress=False
    )
    assert np.mean(losses[-5:]) < np.mean(losses[:5])


def test_schedule_warms_up_and_decays() -> None:
    assert learning_rate_at(0.0, 1.0) < learning_rate_at(0.05, 1.0) == pytest.approx(1.0)
    assert learning_rate_at(1.0, 1.0) == pytest.approx(0.05)


def test_site_patches_carry_their_vectors(drawn_site: Path) -> None:
    rasters = load_site_rasters(drawn_site)
    grid = site_grid(rasters, TINY)
    assert grid.image.shape == (8, 160, 240)  # 40 m x 60 m at 0.25 m/px
    centre_global = grid.global_from_pixel(grid.pixel_from_global(np.array([[520.0, 780.0]])))
    assert np.allclose(centre_global, [[520.0, 780.0]])
    sample = random_site_sample(grid, read_vectors(vector_map_of(drawn_site)), TINY, np.random.default_rng(1))
    assert sample.image.shape == (8, 64, 64)
    assert len(sample.labels) >= 1 and sample.points.shape[1:] == (6, 2)
    assert (sample.points >= 0).all() and (sample.points <= 1).all()
    sampler = mixed_sampler([], TINY, 0.0)  # no sites: procedural only
    assert sampler(np.random.default_rng(2)).image.shape == (8, 64, 64)


def test_whole_site_inference_returns_global_vectors(drawn_site: Path) -> None:
    rasters = load_site_rasters(drawn_site)
    model = VmaNet(TINY).eval()
    torch.nn.init.constant_(model.class_head[-1].bias, 3.0)  # every query fires: exercises merging
    vectors = predict_site(model, rasters, InferenceConfig(overlap_px=16), show_progress=False)
    assert vectors
    xmin, xmax, ymin, ymax = rasters.extent()
    for v in vectors:
        assert 0.0 <= v.score <= 1.0
        assert (v.points[:, 0] > xmin - 20).all() and (v.points[:, 0] < xmax + 20).all()
        assert (v.points[:, 1] > ymin - 20).all() and (v.points[:, 1] < ymax + 20).all()
