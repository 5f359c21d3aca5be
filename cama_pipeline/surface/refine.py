"""Multi-view refinement of the road elevation: the heights at which every camera sees the same road.

Why: the elevation MLP is fitted to points (the trajectory strip and SfM road points), which are dense only
under the cameras. A height error moves a cell's projection along the ground by the error times range over
camera height, so a centimetre or two is enough for the views of one lane line or crossing stripe to land
side by side, and the observation vote smears them. On the default site with true poses the BEV lane-marking
IoU is 0.60 with the fitted elevation and 0.78 with the true road elevation, crossings 0.90 against 0.99
(`bench/surface_split.py`).

How: a plane sweep on the height field, the multi-view stereo of a surface that is known up to a few
centimetres. For each of a sample of vertices (every `vertex_stride`-th along rows and columns) and each
height hypothesis around the current surface, every image that sees the vertex is sampled where the vertex
would project at that height; the hypothesis at which the views agree best (least weighted variance of the
colour and of the class frequencies, the photo-consistency that also decides the kerb steps in `steps`) is
the vertex's height. Only vertices voted a road class count: a kerb or sidewalk stands above the road on a
step that the 1 m control grid cannot hold. The vertices' cost curves are summed per control point of the
elevation's grid; its best height (parabola through the minimum) and confidence (how far the minimum drops
below the curve's mean: plain asphalt looks the same at every height and gets none) feed a sparse
least-squares solve with a thin-plate penalty, whose result is added to `Mesh.offset`. A coarse sweep, then a
fine one around it.

RoMe optimises the same photometric and semantic agreement by gradient descent through a differentiable
renderer; here Adam on the control-grid residual was tried first and walked the well-fitted heights near the
trajectory away (0.57 -> 1.2 cm RMSE within 2 m, default site, true poses): the per-point gradients of
sharp images are sparse and noisy, and Adam's per-parameter normalisation turns them into steps of full
size. The sweep finds each height from all views at once.
"""

import math
from dataclasses import dataclass, replace

import numpy as np
import torch
import torch.nn.functional as F
from scipy import ndimage, sparse
from scipy.sparse.linalg import spsolve

from cama_pipeline.cameras import CameraView
from cama_pipeline.data import Dataset
from cama_pipeline.semantics import BEV_CLASSES, ROAD_SURFACE_IDS
from cama_pipeline.surface.config import SurfaceConfig
from cama_pipeline.surface.observe import GROUND, Camera, image_channels, pixel_area, sample_images
from cama_pipeline.surface.optimise import Advance, Mesh, batches, visible_ids
from cama_pipeline.surface.steps import VARIANCE_FLOOR, ColourMoments

VALUES = 3 + len(BEV_CLASSES)
"""Per sample: RGB and the class frequencies."""


def refine_steps(views: int, config: SurfaceConfig) -> int:
    """Images `refine_elevation` goes through (for progress): every image once per sweep."""
    return views * len(config.refine.sweeps) if config.refine.enabled else 0


def downsampled(camera: Camera, factor: int) -> Camera:
    """The camera of its image averaged over `factor` x `factor` pixel blocks (pixel centres at integers)."""
    if factor == 1:
        return camera
    return replace(
        camera,
        fx=camera.fx / factor,
        fy=camera.fy / factor,
        cx=(camera.cx + 0.5) / factor - 0.5,
        cy=(camera.cy + 0.5) / factor - 0.5,
        width=-(-camera.width // factor),
        height=-(-camera.height // factor),
    )


def pooled(images: torch.Tensor, factor: int) -> torch.Tensor:
    """(B, C, H, W) images averaged over `factor` x `factor` blocks (a partial block at the edge too)."""
    if factor == 1:
        return images
    return F.avg_pool2d(images, factor, ceil_mode=True, count_include_pad=False)


@dataclass(eq=False)
class SweepVotes:
    """Weighted moments of every sampled vertex's samples at every height hypothesis."""

    moments: ColourMoments
    """Rows vertex * hypotheses + hypothesis; channels RGB and the class frequencies; weights are the pixels
    covered on ground."""
    views: torch.Tensor
    """(S,) images that see the vertex on ground at the middle hypothesis."""
    hypotheses: int

    @classmethod
    def empty(cls, vertices: int, hypotheses: int, device: torch.device) -> "SweepVotes":
        moments = ColourMoments(vertices * hypotheses, device, channels=VALUES)
        return cls(moments, torch.zeros(vertices, device=device), hypotheses)

    def cost(self, semantic_weight: float) -> torch.Tensor:
        """(S, H) weighted variance across views of the colour plus `semantic_weight` times that of the
        class frequencies."""
        variance = self.moments.channel_variance().view(-1, self.hypotheses, VALUES)
        return variance[..., :3].sum(-1) + semantic_weight * variance[..., 3:].sum(-1)

    def road(self) -> torch.Tensor:
        """(S,) seen by two images or more at every hypothesis and voted a road class at the middle one."""
        weight = self.moments.weight.view(-1, self.hypotheses)
        middle = self.hypotheses // 2
        classes = self.moments.sum.view(-1, self.hypotheses, VALUES)[:, middle, 3:].argmax(dim=1)
        road_ids = torch.tensor(ROAD_SURFACE_IDS, device=classes.device)
        return (self.views >= 2) & (weight > 0).all(dim=1) & torch.isin(classes, road_ids)


def refine_elevation(
    mesh: Mesh, dataset: Dataset, views: list[CameraView], config: SurfaceConfig, advance: Advance
) -> list[dict[str, float]]:
    """Add the sweeps' residual to `mesh.offset` (see the module docstring); per sweep: its step, the control
    points it constrained and the residual's RMS and largest magnitude (m) after it."""
    refine = config.refine
    history: list[dict[str, float]] = []
    if not refine.enabled:
        return history
    device = mesh.vertex_xy.device
    sample = sampled_vertices(mesh, refine.vertex_stride)
    local = torch.full((len(mesh.vertex_xy),), -1, dtype=torch.long, device=device)
    local[sample] = torch.arange(len(sample), device=device)
    visible: list[torch.Tensor] = []
    for half, step in refine.sweeps:
        hypotheses = torch.arange(-round(half / step), round(half / step) + 1, device=device) * step
        with torch.no_grad():
            control_z = mesh.control_heights()
            heights = mesh.control.at_vertices(control_z)
            if not visible:
                visible = [_sampled_visible(mesh, heights, view, local, config) for view in views]
            votes = sweep(mesh, dataset, views, visible, local, heights, hypotheses, config, advance)
        best, confidence = control_point_heights(mesh, sample, votes, hypotheses, config)
        residual = smooth_residual(best, confidence, refine.smoothness_weight, refine.ridge_weight)
        mesh.offset = mesh.offset + torch.as_tensor(residual, dtype=mesh.offset.dtype, device=device)
        total = mesh.offset.detach()
        history.append(
            {
                "step_m": step,
                "control_points_constrained": int((confidence > 0).sum()),
                "offset_rms_m": float(total.square().mean().sqrt()),
                "offset_max_m": float(total.abs().max()),
            }
        )
    return history


def sampled_vertices(mesh: Mesh, stride: int) -> torch.Tensor:
    """Ids of the vertices on every `stride`-th row and column of the grid."""
    rows, cols = mesh.grid.vertex_cells()
    keep = np.flatnonzero((rows % stride == 0) & (cols % stride == 0))
    return torch.as_tensor(keep, dtype=torch.long, device=mesh.vertex_xy.device)


def _sampled_visible(
    mesh: Mesh, heights: torch.Tensor, view: CameraView, local: torch.Tensor, config: SurfaceConfig
) -> torch.Tensor:
    """The sampled vertices one view sees (z-buffer tested against every vertex), as global ids."""
    ids = visible_ids(mesh, heights, Camera.of(view, mesh.vertex_xy.device), config)
    return ids[local[ids] >= 0]


def sweep(
    mesh: Mesh,
    dataset: Dataset,
    views: list[CameraView],
    visible: list[torch.Tensor],
    local: torch.Tensor,
    heights: torch.Tensor,
    hypotheses: torch.Tensor,
    config: SurfaceConfig,
    advance: Advance,
) -> SweepVotes:
    """The moments of the sampled vertices (`local`: each vertex's index among them, -1 when not sampled)
    at each height of `hypotheses` (m above `heights`), over all images (`visible`: the sampled vertices
    each sees)."""
    device = mesh.vertex_xy.device
    count = len(hypotheses)
    votes = SweepVotes.empty(int((local >= 0).sum()), count, device)
    normals = mesh.control.normals(mesh.control_heights())
    factor = config.refine.downsample
    for indices in batches(views, config.images_per_batch):
        images = pooled(image_channels(dataset, [views[i] for i in indices], device), factor)
        for b, i in enumerate(indices):
            ids = visible[i]
            if not len(ids):
                continue
            camera = downsampled(Camera.of(views[i], device), factor)
            xyz = torch.cat([mesh.vertex_xy[ids], heights[ids].double()[:, None]], dim=1)
            shifted = xyz[None].repeat(count, 1, 1)
            shifted[..., 2] += hypotheses.double()[:, None]
            uv, _, cam = camera.project(shifted.reshape(-1, 3))
            area = pixel_area(camera, cam, normals[ids].repeat(count, 1), mesh.grid.resolution_m)
            samples = sample_images(images[b : b + 1], uv[None])[0]
            ground = samples[:, GROUND]
            values = torch.cat(
                [samples[:, :3], samples[:, 3:GROUND] / ground.clamp(min=1e-6)[:, None]], dim=1
            )
            weight = area * ground
            slot = local[ids].repeat(count) * count + torch.arange(count, device=device).repeat_interleave(
                len(ids)
            )
            votes.moments.add(slot, values, weight)
            middle = ground.reshape(count, -1)[count // 2] > 0
            votes.views.index_add_(0, local[ids][middle], torch.ones(int(middle.sum()), device=device))
        advance(len(indices), math.nan)
    return votes


def inner_road(rows: np.ndarray, cols: np.ndarray, road: np.ndarray, config: SurfaceConfig) -> np.ndarray:
    """(S,) the sampled road vertices (grid `rows`, `cols`) with no other sampled vertex within
    `refine.edge_margin_m` that is not road (off-road, unobserved or seen once): near a kerb some views see
    its face or top where the road should be, and the step is no height of the road."""
    stride = config.refine.vertex_stride
    lattice = np.zeros((rows.max(initial=0) // stride + 1, cols.max(initial=0) // stride + 1), bool)
    lattice[rows // stride, cols // stride] = road
    reach = int(np.ceil(config.refine.edge_margin_m / (stride * config.resolution_m)))
    if reach > 0:
        disk = np.hypot(*np.mgrid[-reach : reach + 1, -reach : reach + 1]) <= reach
        lattice = ndimage.binary_erosion(lattice, disk, border_value=0)
    return road & lattice[rows // stride, cols // stride]


def control_point_heights(
    mesh: Mesh, sample: torch.Tensor, votes: SweepVotes, hypotheses: torch.Tensor, config: SurfaceConfig
) -> tuple[np.ndarray, np.ndarray]:
    """(rows, cols) of the control grid twice: each control point's best height above the current surface
    (the minimum of its road vertices' summed cost curves, refined by a parabola) and its confidence (the
    minimum's drop below the curve's mean, as a share of the mean plus `steps.VARIANCE_FLOOR`, so that
    the noise of a flat curve is no evidence, times the share of its vertices that are road;
    0 where it has none)."""
    control = mesh.control
    spacing = round(control.spacing_m / mesh.grid.resolution_m)
    rows, cols = mesh.grid.vertex_cells()
    ids = sample.cpu().numpy()
    road = inner_road(rows[ids], cols[ids], votes.road().cpu().numpy(), config)
    cost = votes.cost(config.refine.semantic_weight).cpu().numpy().astype(np.float64)[road]
    flat = np.round(rows[ids][road] / spacing).astype(np.int64) * control.cols
    flat += np.round(cols[ids][road] / spacing).astype(np.int64)
    points = control.rows * control.cols
    count = np.bincount(flat, minlength=points)
    summed = [np.bincount(flat, cost[:, h], minlength=points) for h in range(cost.shape[1])]
    curve = np.stack(summed, axis=1) / np.maximum(count, 1)[:, None]
    best_index = curve.argmin(axis=1)
    inner = np.clip(best_index, 1, curve.shape[1] - 2)
    before, at, after = (curve[np.arange(points), inner + k] for k in (-1, 0, 1))
    bend = before - 2 * at + after
    shift = np.where(bend > 0, 0.5 * (before - after) / np.where(bend > 0, bend, 1), 0.0)
    shift = np.where(best_index == inner, np.clip(shift, -0.5, 0.5), 0.0)
    step = float(hypotheses[1] - hypotheses[0]) if len(hypotheses) > 1 else 0.0
    best = hypotheses.cpu().numpy()[best_index] + shift * step
    mean = curve.mean(axis=1)
    drop = (mean - curve.min(axis=1)) / (mean + VARIANCE_FLOOR)
    expected = (spacing / config.refine.vertex_stride) ** 2
    confidence = np.where(count > 0, drop * np.minimum(count / expected, 1.0), 0.0)
    return best.reshape(control.rows, control.cols), confidence.reshape(control.rows, control.cols)


def _differences(length: int, order: int) -> sparse.csr_matrix:
    """(length - order, length) first or second differences (empty when the grid is too short)."""
    if length <= order:
        return sparse.csr_matrix((0, length))
    stencil = [-1.0, 1.0] if order == 1 else [1.0, -2.0, 1.0]
    return sparse.diags(stencil, list(range(order + 1)), shape=(length - order, length), format="csr")


def smooth_residual(best: np.ndarray, confidence: np.ndarray, smoothness: float, ridge: float) -> np.ndarray:
    """(rows, cols) residual minimising sum confidence * (r - best)^2 + smoothness * its thin-plate energy
    (squared second differences along rows and columns, twice the squared mixed difference) + ridge * r^2."""
    rows, cols = best.shape
    along_rows = sparse.kron(_differences(rows, 2), sparse.identity(cols))
    along_cols = sparse.kron(sparse.identity(rows), _differences(cols, 2))
    mixed = sparse.kron(_differences(rows, 1), _differences(cols, 1))
    energy = along_rows.T @ along_rows + along_cols.T @ along_cols + 2 * mixed.T @ mixed
    weight = confidence.ravel()
    system = sparse.diags(weight + ridge) + smoothness * energy
    return np.asarray(spsolve(system.tocsc(), weight * best.ravel())).reshape(rows, cols)
