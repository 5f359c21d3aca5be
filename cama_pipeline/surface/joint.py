"""Joint optimisation of the mesh against the images by differentiable rendering (RoMe's reconstruction).

After the observation vote has set every vertex's colour, semantic logits and kerb step, `epochs` of Adam render
the mesh into every keyframe image (`render`: each sampled ground pixel's ray cast onto the height field) and
minimise, over the rays that hit the road region,
  the L1 error between the rendered and the pixel colour,
  `semantic_weight` times the cross-entropy between the rendered logits and the pixel's class in the image mask,
  `smoothness_weight` times the squared height differences of neighbouring vertices, each pair weighted by
  `edge_weight` where a road class meets an off-road class (so a kerb can stand as a step there),
  `ridge_weight` times the squared residual (where nothing is seen, the surface stays where the fit put it),
over four sets of parameters together: the per-vertex colours, the per-vertex logits, a lift of the smooth surface
on its control grid (the elevation MLP's 1 m grid, added to the refinement's offset: a height is seen by the many
pixels of a square metre together, as RoMe's elevation MLP pools them) and a per-vertex height residual on top (a
kerb's step is a few cells wide). Only ground pixels take part (the mask's
road classes, curb and background), so dynamic objects, the ego body and the sky never pull the surface.

A pixel is rendered by one ray, where its bilinear weights spread over the four vertices around the hit, so every
pixel counts once and a cell is pulled only by the pixels that really see it (its face, for a kerb seen from the
road); the vote, in contrast, samples each vertex in every image at its projection, occluded or not, once the depth
test has passed. Afterwards the kerb steps and the residual are one surface (`Mesh.residual`), which `vote_after`
votes colour and class on again (`vote_config`), and which the export splits into road level and kerb step
(`road_and_step`). Measured against the vote in `bench/surface_joint.py`: it does not improve on it (README).
"""

import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
import torch
import torch.nn.functional as F

from cama_pipeline.cameras import CameraView
from cama_pipeline.data import Dataset
from cama_pipeline.semantics import ROAD_SURFACE_IDS
from cama_pipeline.surface.config import SurfaceConfig
from cama_pipeline.surface.observe import GROUND, Camera, image_channels
from cama_pipeline.surface.optimise import Mesh, batches
from cama_pipeline.surface.render import HeightField, cast_rays, dense_heights, vertex_cells_flat

Advance = Callable[[int, float], None]


@dataclass(frozen=True, eq=False)
class Rays:
    """Sampled ground pixels of a batch of images and their rays."""

    origin: torch.Tensor
    """(N, 3) float64 camera centres, global metres."""
    direction: torch.Tensor
    """(N, 3) float64 unit rays, world frame."""
    colour: torch.Tensor
    """(N, 3) RGB in [0, 1]."""
    label: torch.Tensor
    """(N,) long: the pixel's BEV class."""


def sample_rays(images: torch.Tensor, cameras: list[Camera], count: int, generator: torch.Generator) -> Rays:
    """`count` ground pixels drawn uniformly per image (fewer when it has fewer), as rays."""
    parts: list[tuple[torch.Tensor, ...]] = []
    for image, camera in zip(images, cameras, strict=True):
        ground = image[GROUND].reshape(-1) > 0.5
        pixels = torch.nonzero(ground)[:, 0]
        if len(pixels) == 0:
            continue
        pick = pixels[torch.randperm(len(pixels), generator=generator)[:count].to(pixels.device)]
        v, u = pick // camera.width, pick % camera.width
        ones = torch.ones(len(u), device=u.device)
        local = torch.stack([(u - camera.cx) / camera.fx, (v - camera.cy) / camera.fy, ones], 1)
        world = local.double() @ camera.cam_from_world_R
        direction = world / world.norm(dim=1, keepdim=True)
        origin = torch.as_tensor(camera.centre, dtype=torch.float64, device=u.device).expand(len(u), 3)
        flat = image.reshape(image.shape[0], -1)[:, pick].T
        parts.append((origin, direction, flat[:, :3], flat[:, 3:GROUND].argmax(dim=1)))
    if not parts:
        empty = torch.zeros((0, 3), dtype=torch.float64, device=images.device)
        return Rays(empty, empty, empty.float(), torch.zeros(0, dtype=torch.long, device=images.device))
    origin, direction, colour, label = (torch.cat(column) for column in zip(*parts, strict=True))
    return Rays(origin, direction, colour, label)


def neighbour_pairs(mesh: Mesh, edge_weight: float) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """(E,) vertex ids of every pair of row- or column-adjacent vertices and each pair's smoothness weight:
    `edge_weight` where one is labelled a road class and the other not (a kerb's edge), else 1."""
    ids = mesh.grid.vertex_id
    pairs = [
        np.stack([ids[:, :-1].ravel(), ids[:, 1:].ravel()], axis=1),
        np.stack([ids[:-1, :].ravel(), ids[1:, :].ravel()], axis=1),
    ]
    both = np.concatenate(pairs)
    both = both[(both >= 0).all(axis=1)]
    a = torch.as_tensor(both[:, 0], device=mesh.vertex_xy.device)
    b = torch.as_tensor(both[:, 1], device=mesh.vertex_xy.device)
    road = torch.isin(mesh.logits.argmax(dim=1), torch.tensor(ROAD_SURFACE_IDS, device=a.device))
    weight = torch.where(road[a] != road[b], edge_weight, 1.0)
    return a, b, weight


def render_optimise(
    mesh: Mesh, dataset: Dataset, views: list[CameraView], config: SurfaceConfig, advance: Advance
) -> list[dict[str, float]]:
    """`config.joint.epochs` of Adam (see the module docstring); sets mesh.colour, logits and residual; returns
    per-epoch mean losses and the share of rays that hit the region."""
    joint = config.joint
    if joint.epochs == 0:
        return []
    device = mesh.vertex_xy.device
    generator = torch.Generator().manual_seed(config.seed)
    with torch.no_grad():
        control = mesh.control_heights().detach()
    colour = mesh.colour.clone().requires_grad_(True)
    logits = mesh.logits.clone().requires_grad_(True)
    lift = torch.zeros_like(control, requires_grad=True)
    residual = torch.zeros_like(mesh.step, requires_grad=True)
    optimiser = torch.optim.Adam(
        [
            {"params": [colour], "lr": joint.colour_lr},
            {"params": [logits], "lr": joint.semantic_lr},
            {"params": [lift], "lr": joint.height_lr},
            {"params": [residual], "lr": joint.vertex_height_lr},
        ]
    )
    pair_a, pair_b, pair_weight = neighbour_pairs(mesh, joint.edge_weight)
    vertex_id = torch.as_tensor(mesh.grid.vertex_id, device=device)
    smooth = mesh.control.at_cells(control)
    cells = vertex_cells_flat(mesh.grid).to(device)
    history: list[dict[str, float]] = []
    for _ in range(joint.epochs):
        totals = np.zeros(4)
        steps = 0
        for indices in batches(views, joint.images_per_batch):
            cameras = [Camera.of(views[i], device) for i in indices]
            images = image_channels(dataset, [views[i] for i in indices], device)
            rays = sample_rays(images, cameras, joint.rays_per_image, generator)
            optimiser.zero_grad()
            height = mesh.control.at_vertices(control + lift) + mesh.step + residual
            attributes = torch.cat([colour, logits], dim=1)
            field = HeightField(
                mesh.grid, vertex_id, height, attributes, smooth, dense_heights(smooth, cells, height)
            )
            hits = cast_rays(
                field, rays.origin, rays.direction, config.max_range_m, joint.search_m, joint.samples
            )
            values, inside = field.attributes_at(hits.xy)
            used = hits.valid & inside
            if not used.any():  # no ray of the batch came down onto the region: nothing to learn from it
                advance(len(indices), math.nan)
                continue
            shown = values[used]
            colour_loss = (shown[:, :3] - rays.colour[used]).abs().sum(dim=1).mean()
            semantic_loss = F.cross_entropy(shown[:, 3:], rays.label[used])
            roughness = (pair_weight * (residual[pair_a] - residual[pair_b]) ** 2).mean()
            ridge = (residual**2).mean() + (lift**2).mean()
            loss = (
                colour_loss
                + joint.semantic_weight * semantic_loss
                + joint.smoothness_weight * roughness
                + joint.ridge_weight * ridge
            )
            loss.backward()
            optimiser.step()
            totals += [colour_loss.item(), semantic_loss.item(), loss.item(), float(used.float().mean())]
            steps += 1
            advance(len(indices), loss.item())
        mean = totals / max(steps, 1)
        history.append(
            {"colour_l1": mean[0], "semantic_ce": mean[1], "loss": mean[2], "rays_hitting": mean[3]}
        )
    mesh.colour = colour.detach().clamp(0, 1)
    mesh.logits = logits.detach()
    mesh.offset = mesh.offset + lift.detach()
    mesh.residual = (mesh.step + residual).detach()
    mesh.step = torch.zeros_like(mesh.step)
    return [{name: float(value) for name, value in row.items()} for row in history]


def vote_config(config: SurfaceConfig) -> SurfaceConfig:
    """The observation vote on the jointly optimised surface: one height per cell (its kerb steps and residual are
    in the surface now), so no second vote at curb height and no new steps."""
    return replace(config, curb_height_m=0.0, kerb_step=replace(config.kerb_step, enabled=False))


def road_and_step(
    base: np.ndarray, step: np.ndarray, residual: np.ndarray, labels: np.ndarray, curb_height_m: float
) -> tuple[np.ndarray, np.ndarray]:
    """Per-vertex (road-level elevation, kerb step) from the smooth surface, the vote's step and the residual: an
    off-road vertex standing more than half the curb height above the smooth surface is on a step (its elevation
    the road level below it, `outputs`); every other vertex's elevation is its surface. Without a residual this
    is the vote's split unchanged."""
    above = step + residual
    raised = (above > curb_height_m / 2) & ~np.isin(labels, ROAD_SURFACE_IDS)
    return np.where(raised, base, base + above), np.where(raised, above, 0.0)
