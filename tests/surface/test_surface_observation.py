"""Observation count against a hand-countable scene, and unobserved cells marked as such in every raster."""

from dataclasses import dataclass

import numpy as np
import torch

from cama_pipeline.cameras import CameraView
from cama_pipeline.semantics import Semantic
from cama_pipeline.surface.config import SurfaceConfig
from cama_pipeline.surface.elevation import new_elevation_mlp
from cama_pipeline.surface.grid import SurfaceGrid
from cama_pipeline.surface.observe import Camera, visible_vertices
from cama_pipeline.surface.optimise import new_mesh, observe
from cama_pipeline.surface.outputs import rasters_from_vertices

WIDTH, HEIGHT, FOCAL_PX, ALTITUDE_M = 8, 6, 10.0, 10.0
"""A camera 10 m above a flat plane looking straight down with f = 10 px: each 1 m cell is exactly one pixel."""


@dataclass(frozen=True)
class FakeImage:
    semantic: np.ndarray

    def load_rgb(self) -> np.ndarray:
        return np.full((HEIGHT, WIDTH, 3), 128, np.uint8)

    def load_semantic(self) -> np.ndarray:
        return self.semantic


class FakeDataset:
    """Serves the masks by token, as `Dataset.image(token)` does."""

    def __init__(self, masks: dict[str, np.ndarray]):
        self.masks = masks

    def image(self, token: str) -> FakeImage:
        return FakeImage(self.masks[token])


def down_camera(token: str, x: float, y: float) -> CameraView:
    """A camera at (x, y, 10) looking down: image x along world +x, image rows along world -y."""
    world_from_cam = np.eye(4)
    world_from_cam[:3, :3] = np.diag([1.0, -1.0, -1.0])
    world_from_cam[:3, 3] = [x, y, ALTITUDE_M]
    K = np.array([[FOCAL_PX, 0, (WIDTH - 1) / 2], [0, FOCAL_PX, (HEIGHT - 1) / 2], [0, 0, 1]])
    return CameraView(token, token, "scene", "CAM", 0, 0, world_from_cam, np.eye(4), K, WIDTH, HEIGHT)


def flat_mesh(config: SurfaceConfig):
    """A 20 x 20 grid of 1 m cells (x 0..19, y 19..0) on the plane z = 0."""
    grid = SurfaceGrid((0.0, 19.0), 1.0, 20, 20, np.arange(400).reshape(20, 20))
    mlp = new_elevation_mlp(grid, np.zeros(1), config)
    with torch.no_grad():
        mlp.net[-1].weight.zero_()
        mlp.net[-1].bias.zero_()
    return new_mesh(grid, mlp, config, torch.device("cpu"))


def test_observation_count_is_the_pixels_that_hit_each_cell() -> None:
    config = SurfaceConfig(resolution_m=1.0, control_spacing_m=1.0, max_range_m=25.0)
    mesh = flat_mesh(config)
    road = np.full((HEIGHT, WIDTH), int(Semantic.ROAD), np.uint8)
    with_car = road.copy()
    with_car[:, WIDTH - 1] = int(Semantic.VEHICLE)  # the last image column sees a vehicle, not the road
    views = [down_camera("a", 5.5, 9.5), down_camera("b", 9.5, 9.5)]
    dataset = FakeDataset({"a": road, "b": with_car})
    observe(mesh, dataset, views, config, lambda done, loss: None)  # type: ignore[arg-type]
    labels = mesh.logits.argmax(dim=1).numpy().astype(np.uint8)
    heights = np.zeros(400, np.float32)
    rasters = rasters_from_vertices(mesh.grid, heights, mesh.colour.numpy(), labels, mesh.count.numpy())

    expected = np.zeros((20, 20), np.uint16)
    expected[7:13, 2:10] += 1  # camera a: x 2..9, y 12..7 (rows 7..12)
    expected[7:13, 6:13] += 1  # camera b: x 6..13 but the vehicle column x = 13 does not count
    np.testing.assert_array_equal(rasters.observation_count, expected)
    seen = expected > 0
    assert np.all(rasters.semantic[seen] == int(Semantic.ROAD))
    assert np.all(rasters.semantic[~seen] == int(Semantic.UNOBSERVED))
    assert np.all(np.isnan(rasters.elevation[~seen])) and not np.isnan(rasters.elevation[seen]).any()
    assert np.all(rasters.photometric_rgb[~seen] == 0)
    np.testing.assert_allclose(rasters.photometric_rgb[seen], 128, atol=1)


def test_a_vertex_behind_a_nearer_one_on_the_same_ray_is_hidden() -> None:
    config = SurfaceConfig(resolution_m=0.1)
    camera = Camera.of(down_camera("a", 5.5, 9.5), torch.device("cpu"))
    # two vertices on the ray through pixel (0, 0): 4 m and 10 m below the camera; and one elsewhere at 10 m
    xyz = torch.tensor([[2.0 + 2.1, 12.0 - 1.5, 6.0], [2.0, 12.0, 0.0], [9.0, 7.0, 0.0]], dtype=torch.float64)
    ids = torch.tensor([10, 11, 12])
    uv, depth, _ = camera.project(xyz)
    np.testing.assert_allclose(uv[0].numpy(), uv[1].numpy(), atol=1e-4)
    np.testing.assert_allclose(depth.numpy(), [4.0, 10.0, 10.0], atol=1e-5)
    assert visible_vertices(camera, xyz, ids, config).tolist() == [10, 12]
    assert visible_vertices(camera, xyz[1:], ids[1:], config).tolist() == [11, 12]
