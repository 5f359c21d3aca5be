"""The elevation MLP: fits a smooth road, and a sharp outlier point does not raise a spike."""

import numpy as np
import pytest
import torch

from cama_pipeline.surface.config import SurfaceConfig
from cama_pipeline.surface.elevation import ControlGrid, fit_elevation, new_elevation_mlp
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


def strip_fit_far_rmse(smoothness_weight: float) -> float:
    """RMSE against the plane of a fit to a 4 m wide strip, over the region 8-12 m beside the strip."""
    xs, ys = np.meshgrid(np.arange(100.0, 160.01, 0.5), np.arange(198.0, 202.01, 0.5))
    xy = np.column_stack([xs.ravel(), ys.ravel()])
    points = np.column_stack([xy, 3 + 0.02 * xy[:, 0] - 0.01 * xy[:, 1]])
    torch.manual_seed(0)
    config = SurfaceConfig(elevation_iterations=400, smoothness_weight=smoothness_weight)
    grid = road_grid(points[:, :2], 0.5, 12.0)
    mlp = new_elevation_mlp(grid, points[:, 2], config)
    region = grid.vertex_xy()
    fit_elevation(mlp, torch.as_tensor(points), config, region_xy=torch.as_tensor(region))
    far = region[np.abs(region[:, 1] - 200.0) > 8.0]
    with torch.no_grad():
        z = mlp(torch.as_tensor(far)).double().numpy()
    return float(np.sqrt(np.mean((z - (3 + 0.02 * far[:, 0] - 0.01 * far[:, 1])) ** 2)))


def test_the_curvature_prior_extrapolates_a_plane_beside_the_points() -> None:
    with_prior = strip_fit_far_rmse(SurfaceConfig.smoothness_weight)
    without = strip_fit_far_rmse(0.0)
    assert with_prior < 0.05  # 8-12 m beside a 4 m strip, within 5 cm of the plane
    assert without > 3 * with_prior  # the check can fail: the bare MLP wanders away from the points


def test_sfm_points_off_the_strip_surface_or_outside_the_region_are_left_out() -> None:
    from cama_pipeline.surface.fit import fit_steps, fit_surface
    from cama_pipeline.surface.points import SurfacePoints

    strip = sloped_road(0.0)
    strip = strip[np.abs(strip[:, 1] - 220.0) <= 2.0]  # a 4 m wide strip along x
    on_road = strip[::7] + np.array([0.0, 5.0, 0.05])  # 5 m beside it, right on the plane
    on_road[:, 2] = 3 + 0.02 * on_road[:, 0] - 0.01 * on_road[:, 1]
    floating = on_road[::2] + np.array([0.3, 0.0, 2.0])  # two metres above the road
    far = on_road[:5] + np.array([0.0, 40.0, 0.0])  # beyond the region around the strip
    sfm = np.concatenate([on_road, floating, far])
    points = SurfacePoints(np.concatenate([strip, sfm]), len(strip), len(sfm))
    torch.manual_seed(0)
    config = SurfaceConfig(resolution_m=0.5, elevation_iterations=150, refit_iterations=100)
    progress: list[int] = []
    fitted = fit_surface(points, config, torch.device("cpu"), lambda steps, _loss: progress.append(steps))
    assert sum(progress) == fit_steps(points, config) == 150 + 4 * 100  # the bar ends at its total
    assert fitted.sfm_kept == len(on_road)
    assert len(fitted.points) == len(strip) + len(on_road)
    assert not fitted.grid.in_region(far[:, :2]).any() and fitted.grid.in_region(on_road[:, :2]).all()


def test_every_cell_of_the_grid_is_interpolated_as_its_vertex_is() -> None:
    xy = np.column_stack([np.linspace(0.0, 23.0, 60), 4.0 * np.sin(np.linspace(0.0, 3.0, 60))])
    grid = road_grid(xy, 0.1, 3.0)
    control = ControlGrid(grid, 1.0, torch.device("cpu"))
    control_z = torch.randn((control.rows, control.cols), generator=torch.Generator().manual_seed(0))
    cells = control.at_cells(control_z)
    rows, cols = grid.vertex_cells()
    assert cells.shape == (grid.rows, grid.cols)
    np.testing.assert_allclose(cells[rows, cols].numpy(), control.at_vertices(control_z).numpy(), atol=1e-6)
    assert (grid.vertex_id < 0).any()  # cells outside the road region are interpolated too
    assert cells[0, 0].item() == pytest.approx(control_z[0, 0].item(), abs=1e-6)


def grade_change_fit(rounds: int) -> tuple[float, int]:
    """A strip on a plane up to x = 130 and SfM points on the road beyond it, whose grade changes there
    (z rises by 0.003 (x - 130)^2 over the plane: 43 cm 12 m on): the fit's largest error at the points 8-12 m past
    the strip's end, and how many points it kept."""
    from cama_pipeline.surface.fit import fit_surface
    from cama_pipeline.surface.points import SurfacePoints

    strip = sloped_road(0.0)
    strip = strip[(np.abs(strip[:, 1] - 220.0) <= 2.0) & (strip[:, 0] <= 130.0)]
    x = np.arange(130.5, 142.01, 0.5)
    sfm = np.column_stack([x, np.full_like(x, 220.0), 3 + 0.02 * x - 0.01 * 220.0 + 0.003 * (x - 130.0) ** 2])
    points = SurfacePoints(np.concatenate([strip, sfm]), len(strip), len(sfm))
    torch.manual_seed(0)
    config = SurfaceConfig(
        resolution_m=0.5,
        elevation_iterations=300,
        refit_iterations=200,
        sfm_gate_m=0.1,  # tight, so that the rounds, not the gate's width, bring the points in
        sfm_gate_rounds=rounds,
    )
    fitted = fit_surface(points, config, torch.device("cpu"))
    far = sfm[sfm[:, 0] >= 138.0]
    with torch.no_grad():
        z = fitted.mlp(torch.as_tensor(far[:, :2])).double().numpy()
    return float(np.abs(z - far[:, 2]).max()), fitted.sfm_kept


def test_points_past_a_grade_change_join_round_by_round() -> None:
    """Gated once against the strip's surface, which continues like a plane, the points past the grade change stay
    out and the surface misses the road there by decimetres; gated again against each new fit they join."""
    once, kept_once = grade_change_fit(1)
    rounds, kept_rounds = grade_change_fit(8)
    assert kept_rounds == 24 > kept_once
    assert once > 0.3 and rounds < 0.06
