"""A painted plane seen by eight oblique cameras, rendered exactly: the scene the surface tests refine and render
against (`test_surface_refine`, `test_surface_joint`), with a mesh whose elevation MLP is a flat plane."""

from dataclasses import dataclass

import numpy as np
import torch

from cama_pipeline.cameras import CameraView
from cama_pipeline.semantics import Semantic
from cama_pipeline.surface.config import RefineConfig, SurfaceConfig
from cama_pipeline.surface.elevation import new_elevation_mlp
from cama_pipeline.surface.grid import SurfaceGrid
from cama_pipeline.surface.optimise import Mesh, new_mesh

WIDTH, HEIGHT, FOCAL_PX, CAMERA_HEIGHT_M = 96, 64, 60.0, 1.5
SUPERSAMPLE = 3
"""Each pixel is the mean of 3 x 3 rays (a camera integrates over its pixel)."""


def paint(x: np.ndarray, y: np.ndarray, painted: bool) -> np.ndarray:
    """Where the ground at (x, y) is paint: blobs of a fixed pattern, or none for bare asphalt."""
    if not painted:
        return np.zeros(x.shape, bool)
    return np.sin(2.1 * x) + np.sin(1.7 * y + 0.5 * x) > 1.0


@dataclass(frozen=True)
class RenderedImage:
    rgb: np.ndarray
    semantic: np.ndarray

    def load_rgb(self) -> np.ndarray:
        return self.rgb

    def load_semantic(self) -> np.ndarray:
        return self.semantic


class RenderedDataset:
    """Serves the rendered images by token, as `Dataset.image(token)` does."""

    def __init__(self, images: dict[str, RenderedImage]):
        self.images = images

    def image(self, token: str) -> RenderedImage:
        return self.images[token]


def oblique_camera(token: str, x: float, y: float, heading: float) -> CameraView:
    """A camera 1.5 m above the ground at (x, y), looking along `heading` (radians from +x), 25 deg down."""
    pitch = np.radians(25.0)
    forward = np.array([np.cos(heading) * np.cos(pitch), np.sin(heading) * np.cos(pitch), -np.sin(pitch)])
    right = np.array([np.sin(heading), -np.cos(heading), 0.0])
    down = np.cross(forward, right)
    world_from_cam = np.eye(4)
    world_from_cam[:3, :3] = np.column_stack([right, down, forward])
    world_from_cam[:3, 3] = [x, y, CAMERA_HEIGHT_M]
    K = np.array([[FOCAL_PX, 0, (WIDTH - 1) / 2], [0, FOCAL_PX, (HEIGHT - 1) / 2], [0, 0, 1]])
    return CameraView(token, token, "scene", "CAM", 0, 0, world_from_cam, np.eye(4), K, WIDTH, HEIGHT)


def render(view: CameraView, painted: bool) -> RenderedImage:
    """The plane z = 0 as the camera sees it: asphalt 80, paint 230 (classes road, lane marking), sky above
    the horizon."""
    offsets = (np.arange(SUPERSAMPLE) + 0.5) / SUPERSAMPLE - 0.5
    v, u, dv, du = np.meshgrid(np.arange(HEIGHT), np.arange(WIDTH), offsets, offsets, indexing="ij")
    K, world_from_cam = view.intrinsic, view.world_from_cam
    rays = np.stack([(u + du - K[0, 2]) / K[0, 0], (v + dv - K[1, 2]) / K[1, 1], np.ones(u.shape)], axis=-1)
    world = rays @ world_from_cam[:3, :3].T
    below = world[..., 2] < -1e-6
    t = np.where(below, -world_from_cam[2, 3] / np.where(below, world[..., 2], -1.0), 0.0)
    x = world_from_cam[0, 3] + t * world[..., 0]
    y = world_from_cam[1, 3] + t * world[..., 1]
    is_paint = paint(x, y, painted) & below
    grey = np.where(is_paint, 230.0, np.where(below, 80.0, 200.0)).mean(axis=(2, 3))
    paint_share = is_paint.mean(axis=(2, 3))
    ground_share = below.mean(axis=(2, 3))
    semantic = np.where(paint_share > 0.5, int(Semantic.LANE_MARKING), int(Semantic.ROAD))
    semantic = np.where(ground_share < 0.5, int(Semantic.SKY), semantic).astype(np.uint8)
    rgb = np.repeat(np.round(grey)[..., None], 3, axis=2).astype(np.uint8)
    return RenderedImage(rgb, semantic)


def scene(painted: bool) -> tuple[list[CameraView], RenderedDataset]:
    """Eight cameras around a 12 x 12 m patch of the plane, two at each side looking across it."""
    views = []
    for i, (x, y, heading) in enumerate(
        [(-1, 3, 0.0), (-1, 8, 0.0), (13, 4, np.pi), (13, 9, np.pi)]
        + [(4, -1, np.pi / 2), (9, -1, np.pi / 2), (3, 13, -np.pi / 2), (8, 13, -np.pi / 2)]
    ):
        views.append(oblique_camera(f"cam-{i}", x, y, heading))
    return views, RenderedDataset({view.token: render(view, painted) for view in views})


def mesh_at(height_m: float, config: SurfaceConfig) -> Mesh:
    """A 12 x 12 m grid of 0.1 m cells (x 0..12, y 12..0) whose elevation MLP is the plane z = height_m."""
    grid = SurfaceGrid((0.0, 12.0), 0.1, 121, 121, np.arange(121 * 121).reshape(121, 121))
    mlp = new_elevation_mlp(grid, np.array([height_m]), config)
    with torch.no_grad():
        mlp.net[-1].weight.zero_()
        mlp.net[-1].bias.zero_()
    return new_mesh(grid, mlp, config, torch.device("cpu"))


CONFIG = SurfaceConfig(
    resolution_m=0.1,
    control_spacing_m=1.0,
    max_range_m=15.0,
    images_per_batch=4,
    refine=RefineConfig(edge_margin_m=0.3),  # the patch is small: keep its edges' vertices
)
