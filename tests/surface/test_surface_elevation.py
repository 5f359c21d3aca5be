"""The elevation MLP: fits a smooth road, and a sharp outlier point does not raise a spike."""

import numpy as np
import pytest
import torch

from cama_pipeline.surface.config import SurfaceConfig
from cama_pipeline.surface.elevation import fit_elevation, new_elevation_mlp
from cama_pipeline.surface.grid import road_grid

OUTLIER_XY = (120.0, 220.0)


def sloped_road(outlier_m: float) -> np.ndarray:
    """Points every metre on a 40 m square of z = 3 + 0.02 x - 0.01 y (global metres), one raised by outlier_m."""
    xs, ys = np.meshgrid(np.arange(100.0, 140.01, 1.0), np.arange(200.0, 240.01, 1.0))
    xy = np.column_stack([xs.ravel(), ys.ravel()])
    z = 3 + 0.02 * xy[:, 0] - 0.01 * xy[:, 1]
    outlier = np.flatnonzero(np.all(np.abs(xy - np.array(OUTLIER_XY)) < 0.3, axis=1))
    z[outlier] += outlier_m
    return np.column_stack([xy, z])


def fitted_error_at(points: np.ndarray, config: SurfaceConfig) -> tuple[float, float]:
    """(|z - plane| at the outlier's place, RMSE over all points against the plane) after the fit."""
    torch.manual_seed(0)
    grid = road_grid(points[:, :2], 0.5, 2.0)
    mlp = new_elevation_mlp(grid, points[:, 2], config)
    fit_elevation(mlp, torch.as_tensor(points), config)
    with torch.no_grad():
        z = mlp(torch.as_tensor(points[:, :2])).double().numpy()
        spike = mlp(torch.tensor([OUTLIER_XY], dtype=torch.float64)).double().item()
    plane = 3 + 0.02 * points[:, 0] - 0.01 * points[:, 1]
    plane_at = 3 + 0.02 * OUTLIER_XY[0] - 0.01 * OUTLIER_XY[1]
    return abs(spike - plane_at), float(np.sqrt(np.mean((z - plane) ** 2)))


@pytest.mark.parametrize("outlier_m", [0.0, 2.0])
def test_a_sharp_outlier_makes_no_spike(outlier_m: float) -> None:
    config = SurfaceConfig(elevation_iterations=400)
    spike, rmse = fitted_error_at(sloped_road(outlier_m), config)
    assert rmse < 0.02
    assert spike < 0.03  # a 2 m outlier moves the surface under it by less than 3 cm


def test_many_octaves_and_a_square_loss_do_follow_the_outlier() -> None:
    """The check can fail: an MLP with many octaves and no robust loss bends towards the outlier."""
    config = SurfaceConfig(elevation_iterations=400, pe_frequencies=10, huber_m=100.0)
    smooth = SurfaceConfig(elevation_iterations=400)
    spike, _ = fitted_error_at(sloped_road(2.0), config)
    spike_smooth, _ = fitted_error_at(sloped_road(2.0), smooth)
    assert spike > 2 * spike_smooth
