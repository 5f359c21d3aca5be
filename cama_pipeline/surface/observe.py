"""Seeing mesh vertices in the keyframe images: projection, visibility and sampling, vectorised in torch.

Each image becomes a (9, H, W) tensor: RGB in [0, 1], the one-hot ground classes 0-4 of its semantic mask
and a `ground` channel (1 where the mask shows a ground class; 0 on vehicles, the ego body, buildings and
sky, which hide the road). A vertex is visible in an image when it projects inside it, in front and within
range, and passes a depth test against a z-buffer rendered from the mesh vertices themselves.

A visible vertex stands for its cell: the camera rays that hit the cell are the pixels its projection
covers, `resolution^2 * |n . d| * fx * fy * r / z^3` (n the surface normal, d the unit ray, r the range,
z the depth), counted only on ground pixels.
"""

from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F

from cama_pipeline.cameras import CameraView
from cama_pipeline.data import Dataset
from cama_pipeline.semantics import BEV_CLASSES
from cama_pipeline.surface.config import SurfaceConfig
from cama_pipeline.surface.grid import SurfaceGrid

CHANNELS = 3 + len(BEV_CLASSES) + 1
"""RGB, one-hot ground classes, ground."""
GROUND = CHANNELS - 1


@dataclass(frozen=True, eq=False)
class Camera:
    """One keyframe camera as torch tensors (global metres, OpenCV axes)."""

    cam_from_world_R: torch.Tensor
    cam_from_world_t: torch.Tensor
    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int
    centre: np.ndarray

    @classmethod
    def of(cls, view: CameraView, device: torch.device) -> "Camera":
        world_from_cam = view.world_from_cam
        R = world_from_cam[:3, :3].T
        t = -R @ world_from_cam[:3, 3]
        K = view.intrinsic
        return cls(
            torch.as_tensor(R, dtype=torch.float64, device=device),
            torch.as_tensor(t, dtype=torch.float64, device=device),
            float(K[0, 0]),
            float(K[1, 1]),
            float(K[0, 2]),
            float(K[1, 2]),
            view.width,
            view.height,
            world_from_cam[:3, 3].copy(),
        )

    def project(self, xyz: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """(N, 2) pixel coordinates (pixel centres at integers), (N,) depth, (N, 3) camera-frame points."""
        cam = (xyz.double() @ self.cam_from_world_R.T + self.cam_from_world_t).float()
        z = cam[:, 2].clamp(min=1e-6)
        uv = torch.stack([self.fx * cam[:, 0] / z + self.cx, self.fy * cam[:, 1] / z + self.cy], dim=1)
        return uv, cam[:, 2], cam


def image_channels(dataset: Dataset, views: list[CameraView], device: torch.device) -> torch.Tensor:
    """(B, 9, H, W) float32 of the views' images (all of one size): RGB, one-hot ground classes and the ground
    channel (see the module docstring), each written straight into the batch (no per-image copies to stack)."""
    classes = torch.arange(len(BEV_CLASSES))[:, None, None]
    batch: torch.Tensor | None = None
    for b, view in enumerate(views):
        image = dataset.image(view.token)
        rgb, labels = torch.from_numpy(image.load_rgb()), torch.from_numpy(image.load_semantic())
        if batch is None:
            batch = torch.empty((len(views), CHANNELS, *labels.shape))
        batch[b, :3] = rgb.permute(2, 0, 1)
        batch[b, 3:GROUND] = labels[None] == classes
        torch.sum(batch[b, 3:GROUND], dim=0, out=batch[b, GROUND])
    if batch is None:
        raise ValueError("image_channels: no views")
    batch[:, :3].div_(255.0)
    return batch.to(device)


def footprint_box(camera: Camera, range_m: float) -> tuple[float, float, float, float]:
    """(xmin, xmax, ymin, ymax) of the camera's frustum cut at depth `range_m`: it holds every point of the
    frustum nearer than `range_m` (depth never exceeds distance)."""
    u = np.array([0.0, camera.width, 0.0, camera.width]) - camera.cx
    v = np.array([0.0, 0.0, camera.height, camera.height]) - camera.cy
    rays = np.column_stack([u / camera.fx, v / camera.fy, np.ones(4)])
    world = rays * range_m @ camera.cam_from_world_R.cpu().numpy() + camera.centre
    xs = np.append(world[:, 0], camera.centre[0])
    ys = np.append(world[:, 1], camera.centre[1])
    return xs.min(), xs.max(), ys.min(), ys.max()


def candidate_vertices(grid: SurfaceGrid, camera: Camera, range_m: float) -> np.ndarray:
    """Vertex ids in the box of the camera's frustum out to `range_m` (a cheap superset of the visible)."""
    xmin, xmax, ymin, ymax = footprint_box(camera, range_m)
    res = grid.resolution_m
    r0 = max(0, int((grid.origin_xy[1] - ymax) / res))
    r1 = min(grid.rows, int((grid.origin_xy[1] - ymin) / res) + 2)
    c0 = max(0, int((xmin - grid.origin_xy[0]) / res))
    c1 = min(grid.cols, int((xmax - grid.origin_xy[0]) / res) + 2)
    window = grid.vertex_id[max(r0, 0) : max(r1, 0), max(c0, 0) : max(c1, 0)]
    return window[window >= 0]


def pixel_area(
    camera: Camera, cam_points: torch.Tensor, normals: torch.Tensor, resolution_m: float
) -> torch.Tensor:
    """(N,) pixels covered by each vertex's cell (see the module docstring); normals in the world frame."""
    depth = cam_points[:, 2].clamp(min=1e-6)
    distance = cam_points.norm(dim=1).clamp(min=1e-6)
    ray_world = (cam_points / distance[:, None]).double() @ camera.cam_from_world_R
    cosine = (ray_world.float() * normals).sum(dim=1).abs()
    return resolution_m**2 * cosine * camera.fx * camera.fy * distance / depth**3


def visible_vertices(
    camera: Camera,
    xyz: torch.Tensor,
    ids: torch.Tensor,
    config: SurfaceConfig,
) -> torch.Tensor:
    """The subset of candidate `ids` (with world points `xyz`) seen by `camera`, z-buffer tested."""
    uv, depth, cam = camera.project(xyz)
    inside = (
        (depth > config.min_depth_m)
        & (cam.norm(dim=1) < config.max_range_m)
        & (uv[:, 0] > -0.5)
        & (uv[:, 0] < camera.width - 0.5)
        & (uv[:, 1] > -0.5)
        & (uv[:, 1] < camera.height - 0.5)
    )
    uv, depth, ids = uv[inside], depth[inside], ids[inside]
    pixel = uv[:, 1].round().long() * camera.width + uv[:, 0].round().long()
    zbuffer = torch.full((camera.width * camera.height,), float("inf"), device=xyz.device)
    zbuffer.scatter_reduce_(0, pixel, depth, reduce="amin")
    front = depth <= zbuffer[pixel] * (1 + config.depth_tolerance) + config.resolution_m
    return ids[front]


def sample_images(images: torch.Tensor, uv: torch.Tensor) -> torch.Tensor:
    """(B, P, C) bilinear samples of (B, C, H, W) images at (B, P, 2) pixel coordinates."""
    height, width = images.shape[-2:]
    grid = torch.stack([uv[..., 0] / (width - 1) * 2 - 1, uv[..., 1] / (height - 1) * 2 - 1], dim=-1)
    sampled = F.grid_sample(images, grid[:, None], mode="bilinear", padding_mode="border", align_corners=True)
    return sampled[:, :, 0].permute(0, 2, 1)
