"""The differentiable height-field renderer: rays land where geometry says, stop on a kerb's face, carry the
gradient of the hit with respect to the heights, and drop rays that never come down within range."""

import numpy as np
import pytest
import torch

from cama_pipeline.semantics import Semantic
from cama_pipeline.surface.grid import SurfaceGrid
from cama_pipeline.surface.joint import road_and_step
from cama_pipeline.surface.render import HeightField, cast_rays, dense_heights, vertex_cells_flat

RESOLUTION_M = 0.1
CAMERA_Z_M = 1.5


def field_of(
    heights: np.ndarray, region: np.ndarray | None = None, requires_grad: bool = False
) -> HeightField:
    """A field on a grid whose cell (row, col) centre is at x = col * 0.1, y = -row * 0.1, with `heights` on the
    region's cells (all cells by default) and a flat smooth surface at 0."""
    rows, cols = heights.shape
    region = np.ones(heights.shape, bool) if region is None else region
    vertex_id = np.full(heights.shape, -1, np.int64)
    vertex_id[region] = np.arange(int(region.sum()))
    grid = SurfaceGrid((0.0, 0.0), RESOLUTION_M, rows, cols, vertex_id)
    smooth = torch.zeros(heights.shape)
    height = torch.tensor(heights[region], dtype=torch.float32, requires_grad=requires_grad)
    attributes = torch.stack([torch.as_tensor(grid.vertex_xy()[:, 0], dtype=torch.float32)], dim=1)
    dense = dense_heights(smooth, vertex_cells_flat(grid), height)
    return HeightField(grid, torch.as_tensor(vertex_id), height, attributes, smooth, dense)


def rays_towards(
    targets_xy: np.ndarray, origin_xy: tuple[float, float] = (1.0, -5.0)
) -> tuple[torch.Tensor, ...]:
    """Rays from a camera 1.5 m above `origin_xy` through the ground points (x, y, 0)."""
    origin = np.array([*origin_xy, CAMERA_Z_M])
    towards = np.column_stack([targets_xy, np.zeros(len(targets_xy))]) - origin
    direction = towards / np.linalg.norm(towards, axis=1, keepdims=True)
    return torch.as_tensor(np.tile(origin, (len(targets_xy), 1))), torch.as_tensor(direction)


def test_rays_land_on_a_flat_field_where_they_meet_the_plane() -> None:
    field = field_of(np.zeros((100, 200)))
    targets = np.array([[3.0, -4.0], [12.5, -6.2], [7.33, -2.05]])
    origin, direction = rays_towards(targets)
    hits = cast_rays(field, origin, direction, 21.0, (0.1, 0.3), 48)
    assert hits.valid.all()
    assert np.allclose(hits.xy.detach().numpy(), targets, atol=1e-3)


def test_a_ray_past_a_kerb_stops_on_its_face_not_on_the_road_behind_it() -> None:
    heights = np.zeros((100, 200))
    heights[:, 100:] = 0.15  # a kerb along x = 9.95 m, the sidewalk beyond it raised
    field = field_of(heights)
    origin, direction = rays_towards(np.array([[10.5, -5.0], [9.0, -5.0]]))
    hits = cast_rays(field, origin, direction, 21.0, (0.1, 0.3), 48)
    x = hits.xy.detach().numpy()[:, 0]
    assert hits.valid.all()
    assert 9.85 <= x[0] <= 10.0  # on the kerb's face (bilinear between the last road and first kerb cell)
    assert x[1] == pytest.approx(9.0, abs=1e-3)  # before the kerb, the road


def test_the_hit_moves_towards_the_camera_as_the_field_rises_as_the_gradient_says() -> None:
    field = field_of(np.zeros((100, 200)), requires_grad=True)
    origin, direction = rays_towards(np.array([[8.0, -5.0]]))
    hits = cast_rays(field, origin, direction, 21.0, (0.1, 0.3), 48)
    hits.xy[0, 0].backward()
    gradient = field.height.grad.sum().item()  # d x_hit / d (all heights raised together)
    raised = field_of(np.full((100, 200), 0.02))
    moved = cast_rays(raised, origin, direction, 21.0, (0.1, 0.3), 48).xy[0, 0].item() - hits.xy[0, 0].item()
    assert gradient < 0
    assert moved / 0.02 == pytest.approx(gradient, rel=0.02)
    assert gradient == pytest.approx((8.0 - 1.0) / -CAMERA_Z_M, rel=0.02)


def test_rays_that_never_come_down_or_land_beyond_range_are_not_rendered() -> None:
    field = field_of(np.zeros((100, 200)))
    origin = torch.tensor([[1.0, -5.0, CAMERA_Z_M]] * 3, dtype=torch.float64)
    direction = torch.tensor([[1.0, 0.0, 0.2], [1.0, 0.0, 0.0], [1.0, 0.0, -0.05]], dtype=torch.float64)
    direction = direction / direction.norm(dim=1, keepdim=True)
    hits = cast_rays(field, origin, direction, 21.0, (0.1, 0.3), 48)
    assert not hits.valid.any()  # up, level, and down but 30 m away


def test_attributes_are_read_only_where_all_four_cells_are_in_the_region() -> None:
    region = np.ones((100, 200), bool)
    region[:, 150:] = False
    field = field_of(np.zeros((100, 200)), region)
    values, inside = field.attributes_at(torch.tensor([[5.05, -3.0], [14.97, -3.0]], dtype=torch.float64))
    assert inside.tolist() == [True, False]
    assert values[0, 0].item() == pytest.approx(5.05, abs=1e-4)  # x interpolated between the cell centres


def test_road_and_step_splits_the_surface_into_road_level_and_kerb_step() -> None:
    base = np.zeros(5)
    step = np.array([0.0, 0.13, 0.13, 0.0, 0.0])
    residual = np.array([0.01, -0.1, 0.02, 0.12, 0.12])
    road, curb, background = int(Semantic.ROAD), int(Semantic.CURB), int(Semantic.BACKGROUND)
    labels = np.array([road, curb, background, curb, road])
    elevation, kerb = road_and_step(base, step, residual, labels, 0.13)
    # the vote's step lowered below half a curb is road level again; a residual alone raises an off-road cell;
    # a road cell is never on a step
    assert np.allclose(elevation, [0.01, 0.03, 0.0, 0.0, 0.12])
    assert np.allclose(kerb, [0.0, 0.0, 0.15, 0.12, 0.0])
    unchanged = road_and_step(base, step, np.zeros(5), labels, 0.13)
    assert np.allclose(unchanged[0], 0.0) and np.allclose(unchanged[1], step)
