"""Mesh optimisation: per-vertex colour and semantic logits (and a refined elevation MLP) from the images.

First pass (`observe`): every keyframe image sees its visible vertices; their weighted mean colour and
class frequencies initialise the mesh (every cell voted again at curb height, where a curb top is seen in
place; see `labels`) and the pixels that hit each cell make the observation count. The off-road cells whose
colours agree better across the views at curb height stand on a kerb step (`steps`) and take their colour
from that height.
Then `epochs` of Adam over image batches minimise the L1 colour error and the semantic cross-entropy of
the vertices projected with the current elevation (differentiable `grid_sample`), weighted by the pixels
each vertex covers and by the ground mask, with the surface-point loss (and the curvature prior) holding
the MLP to the points.
"""

import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F

from cama_pipeline.cameras import CameraView
from cama_pipeline.data import Dataset
from cama_pipeline.semantics import BEV_CLASSES, ROAD_SURFACE_IDS
from cama_pipeline.surface.config import SurfaceConfig
from cama_pipeline.surface.elevation import ControlGrid, ElevationMLP, surface_loss
from cama_pipeline.surface.grid import SurfaceGrid
from cama_pipeline.surface.labels import PAINT, curb_height_logits, curb_logits, fused_logits, shares
from cama_pipeline.surface.observe import (
    GROUND,
    Camera,
    candidate_vertices,
    image_channels,
    pixel_area,
    sample_images,
    visible_vertices,
)
from cama_pipeline.surface.steps import ColourMoments, beyond_kerb_line, raised_vertices

Advance = Callable[[int, float], None]
"""Progress callback: units done in this call (images; Adam steps in the elevation fit), current loss (NaN in a
pass that has none)."""


@dataclass(eq=False)
class Mesh:
    """The surface being optimised: geometry (MLP over the control grid) and per-vertex attributes."""

    grid: SurfaceGrid
    control: ControlGrid
    mlp: ElevationMLP
    vertex_xy: torch.Tensor
    """(V, 2) float64 global metres."""
    colour: torch.Tensor
    """(V, 3) RGB in [0, 1] (a leaf tensor optimised directly)."""
    logits: torch.Tensor
    """(V, 5) semantic logits of the BEV classes."""
    count: torch.Tensor
    """(V,) camera rays (pixels) that hit each vertex's cell."""
    step: torch.Tensor
    """(V,) metres above the elevation MLP: `curb_height_m` on the cells standing at curb height (`steps`),
    else 0."""
    offset: torch.Tensor
    """(rows, cols) metres added to the MLP on its control grid: the photometric refinement's residual
    (`refine`), zeros until it runs."""
    residual: torch.Tensor
    """(V,) metres each vertex's surface stands above the smooth surface after the joint optimisation (`joint`: its
    kerb steps and height residual together), zeros until it runs; every projection of a vertex includes it."""

    def heights(self, control_z: torch.Tensor, ids: torch.Tensor) -> torch.Tensor:
        """Heights of the given vertices: the smooth surface `control_z` plus their residual."""
        return self.control.at_vertices(control_z, ids) + self.residual[ids]

    def control_heights(self) -> torch.Tensor:
        """(rows, cols) the surface on the control grid: the elevation MLP plus the refinement's residual."""
        return self.control.heights(self.mlp) + self.offset


def new_mesh(grid: SurfaceGrid, mlp: ElevationMLP, config: SurfaceConfig, device: torch.device) -> Mesh:
    """A mesh over the grid's vertices with the MLP's geometry; attributes are set by `observe`."""
    empty = torch.zeros(0, device=device)
    vertex_xy = torch.as_tensor(grid.vertex_xy(), device=device)
    control = ControlGrid(grid, config.control_spacing_m, device)
    offset = torch.zeros((control.rows, control.cols), device=device)
    residual = torch.zeros(len(vertex_xy), device=device)
    return Mesh(grid, control, mlp, vertex_xy, empty, empty, empty, empty, offset, residual)


@dataclass(frozen=True, eq=False)
class Batch:
    """Projected vertices of a batch of images, padded to a common length P."""

    ids: torch.Tensor
    """(B, P) vertex ids (0 on padding)."""
    uv: torch.Tensor
    """(B, P, 2) pixel coordinates (differentiable in the elevation)."""
    weight: torch.Tensor
    """(B, P) pixels covered (0 on padding), detached."""


def batches(views: list[CameraView], size: int) -> Iterator[list[int]]:
    """View indices in batches of `size`, each batch of one image size."""
    by_size: dict[tuple[int, int], list[int]] = {}
    for i, view in enumerate(views):
        by_size.setdefault((view.width, view.height), []).append(i)
    for indices in by_size.values():
        for start in range(0, len(indices), size):
            yield indices[start : start + size]


def project_batch(
    mesh: Mesh,
    control_z: torch.Tensor,
    normals: torch.Tensor,
    cameras: list[Camera],
    id_lists: list[torch.Tensor],
) -> Batch:
    """Project each camera's vertices with the current heights into a padded batch."""
    longest = max((len(ids) for ids in id_lists), default=0)
    device = mesh.vertex_xy.device
    ids = torch.zeros((len(cameras), longest), dtype=torch.long, device=device)
    uv = torch.zeros((len(cameras), longest, 2), device=device)
    weight = torch.zeros((len(cameras), longest), device=device)
    rows_uv = []
    for b, (camera, vertex_ids) in enumerate(zip(cameras, id_lists, strict=True)):
        n = len(vertex_ids)
        z = mesh.heights(control_z, vertex_ids)
        xyz = torch.cat([mesh.vertex_xy[vertex_ids], z.double()[:, None]], dim=1)
        projected, _, cam = camera.project(xyz)
        ids[b, :n] = vertex_ids
        weight[b, :n] = pixel_area(camera, cam.detach(), normals[vertex_ids], mesh.grid.resolution_m)
        rows_uv.append(F.pad(projected, (0, 0, 0, longest - n)))
    if rows_uv:
        uv = torch.stack(rows_uv)
    return Batch(ids, uv, weight)


def visible_ids(mesh: Mesh, heights: torch.Tensor, camera: Camera, config: SurfaceConfig) -> torch.Tensor:
    """Vertex ids visible in one camera, given every vertex's height."""
    device = mesh.vertex_xy.device
    candidates = torch.as_tensor(candidate_vertices(mesh.grid, camera, config.max_range_m), device=device)
    xyz = torch.cat([mesh.vertex_xy[candidates], heights[candidates].double()[:, None]], dim=1)
    return visible_vertices(camera, xyz, candidates, config)


def observe(
    mesh: Mesh, dataset: Dataset, views: list[CameraView], config: SurfaceConfig, advance: Advance
) -> list[torch.Tensor]:
    """The averaging pass: sets colour, logits, count and step; returns each view's visible vertex ids (int32)."""
    device = mesh.vertex_xy.device
    vertices = len(mesh.vertex_xy)
    class_sums = torch.zeros((vertices, len(BEV_CLASSES)), device=device)
    raised_sums = torch.zeros((vertices, len(BEV_CLASSES)), device=device)
    road_level, curb_level = ColourMoments(vertices, device), ColourMoments(vertices, device)
    visible: list[torch.Tensor] = [torch.zeros(0, dtype=torch.int32)] * len(views)
    with torch.no_grad():
        control_z = mesh.control_heights()
        normals = mesh.control.normals(control_z)
        heights = mesh.control.at_vertices(control_z) + mesh.residual
        for indices in batches(views, config.images_per_batch):
            cameras = [Camera.of(views[i], device) for i in indices]
            id_lists = [visible_ids(mesh, heights, camera, config) for camera in cameras]
            images = image_channels(dataset, [views[i] for i in indices], device)
            add_votes(class_sums, road_level, mesh, control_z, normals, cameras, id_lists, images)
            if config.curb_height_m > 0:
                raised_z = control_z + config.curb_height_m
                add_votes(raised_sums, curb_level, mesh, raised_z, normals, cameras, id_lists, images)
            for i, ids in zip(indices, id_lists, strict=True):
                visible[i] = ids.to(torch.int32).cpu()
            advance(len(indices), math.nan)
    seen = road_level.weight > 0
    mesh.count = road_level.weight
    at_curb_height = raised_sums[seen] if config.curb_height_m > 0 else None
    mesh.logits = torch.zeros((vertices, len(BEV_CLASSES)), device=device)
    mesh.logits[seen] = fused_logits(class_sums[seen], at_curb_height)
    mesh.colour = road_level.mean()
    mesh.step = torch.zeros(vertices, device=device)
    if config.curb_height_m > 0 and config.kerb_step.enabled:
        classes = mesh.logits.argmax(dim=1)
        off_road = (seen & ~torch.isin(classes, torch.tensor(ROAD_SURFACE_IDS, device=device))).cpu().numpy()
        painted = torch.isin(classes, torch.tensor([int(c) for c in PAINT], device=device)).cpu().numpy()
        line = _beyond_kerb_line(mesh, class_sums, raised_sums, seen, ~off_road & ~painted, config)
        mesh.logits[line] = curb_height_logits(raised_sums[line])
        raised, foot = raised_vertices(mesh.grid, road_level, curb_level, off_road, painted, config.kerb_step)
        raised |= line.cpu().numpy()
        on_step, kerb = torch.as_tensor(raised, device=device), torch.as_tensor(foot, device=device)
        mesh.step[on_step] = config.curb_height_m
        mesh.colour[on_step] = curb_level.mean()[on_step]
        mesh.logits[kerb] = curb_logits(int(kerb.sum()), device)
    return visible


def _beyond_kerb_line(
    mesh: Mesh,
    class_sums: torch.Tensor,
    raised_sums: torch.Tensor,
    seen: torch.Tensor,
    candidates: np.ndarray,
    config: SurfaceConfig,
) -> torch.Tensor:
    """(V,) bool: the road-labelled, unpainted `candidates` beyond the kerb line of the two class votes (`steps`);
    none when `kerb_step.kerb_line` is off."""
    if not config.kerb_step.kerb_line:
        return torch.zeros(len(candidates), dtype=torch.bool, device=class_sums.device)
    line = beyond_kerb_line(
        mesh.grid,
        shares(class_sums).cpu().numpy(),
        shares(raised_sums).cpu().numpy(),
        seen.cpu().numpy(),
        candidates,
        config.kerb_step,
    )
    return torch.as_tensor(line, device=class_sums.device)


def add_votes(
    class_sums: torch.Tensor,
    moments: ColourMoments,
    mesh: Mesh,
    control_z: torch.Tensor,
    normals: torch.Tensor,
    cameras: list[Camera],
    id_lists: list[torch.Tensor],
    images: torch.Tensor,
) -> None:
    """Add the batch's vertices, sampled on the surface `control_z`, to the class votes and colour moments,
    each sample weighted by the pixels its cell covers on ground."""
    batch = project_batch(mesh, control_z, normals, cameras, id_lists)
    samples = sample_images(images, batch.uv)
    weight = (batch.weight * samples[..., GROUND]).reshape(-1)
    ids = batch.ids.reshape(-1)
    class_sums.index_add_(0, ids, samples[..., 3:GROUND].reshape(-1, len(BEV_CLASSES)) * weight[:, None])
    moments.add(ids, samples[..., :3].reshape(-1, 3), weight)


def _batch_loss(
    mesh: Mesh, images: torch.Tensor, batch: Batch, config: SurfaceConfig
) -> tuple[torch.Tensor, torch.Tensor]:
    """Weighted L1 colour and soft cross-entropy semantic losses of one projected batch."""
    samples = sample_images(images, batch.uv)
    ground = samples[..., GROUND]
    weight = (batch.weight * ground).detach()
    total = weight.sum().clamp(min=1e-6)
    colour_error = (mesh.colour[batch.ids] - samples[..., :3]).abs().sum(-1)
    target = samples[..., 3:GROUND] / ground.clamp(min=1e-6)[..., None]
    cross_entropy = -(target * torch.log_softmax(mesh.logits[batch.ids], dim=-1)).sum(-1)
    return (weight * colour_error).sum() / total, (weight * cross_entropy).sum() / total


def optimise(
    mesh: Mesh,
    dataset: Dataset,
    views: list[CameraView],
    visible: list[torch.Tensor],
    points: torch.Tensor,
    config: SurfaceConfig,
    advance: Advance,
) -> list[dict[str, float]]:
    """`config.epochs` of Adam over image batches (see the module docstring); per-epoch mean losses."""
    device = mesh.vertex_xy.device
    generator = torch.Generator().manual_seed(config.seed)
    groups: list[dict[str, Any]] = []
    for tensor, lr in ((mesh.colour, config.colour_lr), (mesh.logits, config.semantic_lr)):
        if lr > 0:
            groups.append({"params": [tensor.requires_grad_(True)], "lr": lr})
    if config.refine_elevation:
        groups.append({"params": list(mesh.mlp.parameters()), "lr": config.refine_lr})
    history: list[dict[str, float]] = []
    if not groups:
        return history
    optimiser = torch.optim.Adam(groups)
    for _ in range(config.epochs):
        totals = np.zeros(3)
        steps = 0
        for indices in batches(views, config.images_per_batch):
            losses = _step(
                mesh, dataset, views, visible, indices, points, config, optimiser, generator, device
            )
            totals += losses
            steps += 1
            advance(len(indices), float(losses[0] + config.semantic_weight * losses[1]))
        mean = totals / max(steps, 1)
        history.append(
            {"colour_l1": float(mean[0]), "semantic_ce": float(mean[1]), "anchor_huber": float(mean[2])}
        )
    mesh.colour = mesh.colour.detach().clamp(0, 1)
    mesh.logits = mesh.logits.detach()
    return history


def _step(
    mesh: Mesh,
    dataset: Dataset,
    views: list[CameraView],
    visible: list[torch.Tensor],
    indices: list[int],
    points: torch.Tensor,
    config: SurfaceConfig,
    optimiser: torch.optim.Optimizer,
    generator: torch.Generator,
    device: torch.device,
) -> np.ndarray:
    """One Adam step on one image batch; its (colour, semantic, anchor) losses."""
    optimiser.zero_grad()
    with torch.set_grad_enabled(config.refine_elevation):
        control_z = mesh.control_heights()
    normals = mesh.control.normals(control_z)
    id_lists = []
    for i in indices:
        ids = visible[i]
        if len(ids) > config.vertices_per_image:
            ids = ids[torch.randperm(len(ids), generator=generator)[: config.vertices_per_image]]
        id_lists.append(ids.long().to(device))
    cameras = [Camera.of(views[i], device) for i in indices]
    batch = project_batch(mesh, control_z, normals, cameras, id_lists)
    images = image_channels(dataset, [views[i] for i in indices], device)
    colour, semantic = _batch_loss(mesh, images, batch, config)
    loss = colour + config.semantic_weight * semantic
    anchor = torch.zeros((), device=device)
    if config.refine_elevation:
        anchor = surface_loss(mesh.mlp, points, mesh.vertex_xy, config, generator)
        loss = loss + config.anchor_weight * anchor
    loss.backward()
    optimiser.step()
    return np.array([colour.item(), semantic.item(), anchor.item()])
