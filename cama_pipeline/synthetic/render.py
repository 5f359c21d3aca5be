"""Vectorised ray casting of the site: the height-field ground and oriented boxes, one image at a time.

Ground: conservative sphere tracing with the terrain's Lipschitz bound, then Newton steps on the
analytic terrain. Boxes: slab tests, restricted to each box's projected bounding rectangle. The nearest
hit wins per pixel (a z-buffer), giving colour, semantic label and instance value together.
"""

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import torch

from cama_pipeline.semantics import Semantic
from cama_pipeline.synthetic.atlas import GroundAtlas
from cama_pipeline.synthetic.config import AppearanceConfig
from cama_pipeline.synthetic.scenery import Boxes, BoxKind
from cama_pipeline.synthetic.shading import NoiseBank, box_color, ground_color, sky_color
from cama_pipeline.synthetic.terrain import Terrain

FAR_M = 220.0
_SPHERE_STEPS = 3
_NEWTON_STEPS = 6
_BOX_LABEL = {
    BoxKind.BUILDING: Semantic.STATIC_OBJECT,
    BoxKind.POLE: Semantic.STATIC_OBJECT,
    BoxKind.CAR: Semantic.VEHICLE,
    BoxKind.EGO: Semantic.EGO,
}


@dataclass(frozen=True)
class World:
    """What the renderer needs of the site: terrain, ground atlas, static boxes, the noise bank and the look."""

    terrain: Terrain
    atlas: GroundAtlas
    static_boxes: Boxes
    noise: NoiseBank
    curb_height_m: float
    look: AppearanceConfig

    @property
    def sun(self) -> torch.Tensor:
        """Direction towards the sun, (3,) float32."""
        return torch.tensor(self.look.sun_direction, dtype=torch.float32)

    def ground_height(self, x: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
        """Height of the ground surface (terrain plus raised sidewalks) at layout points."""
        return self.terrain.height(x, y) + self.curb_height_m * self.atlas.bilinear(self.atlas.raised, x, y)


@dataclass(frozen=True)
class View:
    """A pinhole camera pose to render: layout_from_cam rotation and position, intrinsics, size."""

    layout_from_cam_R: np.ndarray
    layout_from_cam_t: np.ndarray
    K: np.ndarray
    width_px: int
    height_px: int


@dataclass(frozen=True)
class Rendering:
    """An image with its per-pixel labels; `depth_m` is the ray length to the hit (inf for sky)."""

    rgb: np.ndarray  # (H, W, 3) float32 in [0, 1]
    semantic: np.ndarray  # (H, W) uint8 Semantic
    instance: np.ndarray  # (H, W) int32, class * 1000 + element index, 0 = none
    depth_m: np.ndarray  # (H, W) float32


@lru_cache(maxsize=16)
def _camera_rays(k_key: tuple[float, ...], width_px: int, height_px: int) -> torch.Tensor:
    """Unit ray directions in the camera frame for every pixel centre, (H * W, 3) row-major."""
    K = np.asarray(k_key).reshape(3, 3)
    v, u = np.mgrid[0:height_px, 0:width_px]
    pix = np.stack([u.ravel(), v.ravel(), np.ones(u.size)], axis=0).astype(np.float64)
    cam = np.linalg.solve(K, pix).T
    cam /= np.linalg.norm(cam, axis=1, keepdims=True)
    return torch.from_numpy(cam.astype(np.float32))


def pixel_rays(view: View) -> torch.Tensor:
    """Unit ray directions in the layout frame for every pixel centre, shape (H * W, 3), row-major."""
    cam = _camera_rays(tuple(float(k) for k in view.K.ravel()), view.width_px, view.height_px)
    return cam @ torch.from_numpy(view.layout_from_cam_R.T.astype(np.float32))


def intersect_ground(world: World, origin: np.ndarray, dirs: torch.Tensor) -> torch.Tensor:
    """Ray length to the ground per ray (inf where a ray never meets it within FAR_M).

    A few conservative sphere-tracing steps (never past the surface, by the terrain's grade bound) give
    a start from which Newton steps on the ground height converge; only rays that can still hit are kept.
    """
    ox, oy, oz = (float(c) for c in origin)
    result = torch.full((dirs.shape[0],), float("inf"))
    bound_all = world.terrain.cfg.max_grade * torch.linalg.norm(dirs[:, :2], dim=1) - dirs[:, 2]
    idx = torch.nonzero(bound_all > 1e-4).squeeze(1)
    d = dirs[idx]
    bound = bound_all[idx]
    t = torch.full((idx.shape[0],), 0.05)
    for _ in range(_SPHERE_STEPS):
        gap = oz + t * d[:, 2] - world.ground_height(ox + t * d[:, 0], oy + t * d[:, 1])
        t = t + gap.clamp(min=0.0) / bound
        keep = t < FAR_M
        idx, d, bound, t = idx[keep], d[keep], bound[keep], t[keep]
    gap = torch.zeros_like(t)
    for _ in range(_NEWTON_STEPS):
        x, y = ox + t * d[:, 0], oy + t * d[:, 1]
        gap = oz + t * d[:, 2] - world.ground_height(x, y)
        gx, gy = world.terrain.gradient(x, y)
        slope = gx * d[:, 0] + gy * d[:, 1] - d[:, 2]
        t = t + torch.where(slope > 1e-3, gap / slope.clamp(min=1e-3), torch.zeros_like(gap)).clamp(
            -0.5, 20.0
        )
    x, y = ox + t * d[:, 0], oy + t * d[:, 1]
    gap = oz + t * d[:, 2] - world.ground_height(x, y)
    converged = (gap.abs() < 0.02) & (t > 0) & (t < FAR_M)
    result[idx[converged]] = t[converged]
    return result


def render_view(
    world: World, view: View, boxes: Boxes, *, night: bool = False, exposure: float = 1.0
) -> Rendering:
    """Render one camera image with its semantic and instance labels."""
    origin = np.asarray(view.layout_from_cam_t, float)
    dirs = pixel_rays(view)
    n = dirs.shape[0]
    depth = intersect_ground(world, origin, dirs)
    box_id = torch.full((n,), -1, dtype=torch.long)
    face_axis = torch.zeros(n, dtype=torch.long)
    _zbuffer_boxes(view, boxes, origin, dirs, depth, box_id, face_axis)

    rgb = sky_color(dirs[:, 2], world.look)
    semantic = torch.full((n,), int(Semantic.SKY), dtype=torch.uint8)
    instance = torch.zeros(n, dtype=torch.int32)
    focal = float(view.K[0, 0])
    ground = torch.nonzero(torch.isfinite(depth) & (box_id < 0)).squeeze(1)
    if ground.numel():
        _shade_ground(world, origin, dirs[ground], depth[ground], focal, ground, rgb, semantic, instance)
    on_box = torch.nonzero(box_id >= 0).squeeze(1)
    if on_box.numel():
        _shade_boxes(
            world,
            boxes,
            box_id[on_box],
            origin,
            dirs[on_box],
            depth[on_box],
            face_axis[on_box],
            focal,
            on_box,
            rgb,
            semantic,
        )

    visible = torch.isfinite(depth)
    fog = (1.0 - torch.exp(-depth[visible] / 320.0))[:, None]
    rgb[visible] = (
        rgb[visible] + (sky_color(torch.zeros(int(visible.sum())), world.look) - rgb[visible]) * fog
    )
    rgb = rgb * exposure
    if night:
        rgb = 0.02 + 0.16 * rgb**1.3
    shape = (view.height_px, view.width_px)
    return Rendering(
        rgb=rgb.clamp(0, 1).reshape(*shape, 3).numpy(),
        semantic=semantic.reshape(shape).numpy(),
        instance=instance.reshape(shape).numpy(),
        depth_m=depth.reshape(shape).numpy(),
    )


def _shade_ground(
    world: World,
    origin: np.ndarray,
    d: torch.Tensor,
    t: torch.Tensor,
    focal: float,
    sel: torch.Tensor,
    rgb: torch.Tensor,
    semantic: torch.Tensor,
    instance: torch.Tensor,
) -> None:
    """Colour and labels of the pixels whose nearest surface is the ground."""
    x = float(origin[0]) + t * d[:, 0]
    y = float(origin[1]) + t * d[:, 1]
    footprint = t / focal / d[:, 2].abs().clamp(min=0.05).sqrt()  # geometric mean of the footprint axes
    albedo, label, inst = ground_color(world.atlas, world.noise, x, y, footprint, world.look)
    gx, gy = world.terrain.gradient(x, y)
    normal = torch.stack([-gx, -gy, torch.ones_like(gx)], dim=1)
    normal = normal / torch.linalg.norm(normal, dim=1, keepdim=True)
    rgb[sel] = albedo * (0.62 + 0.38 * (normal @ world.sun))[:, None]
    semantic[sel] = label
    instance[sel] = inst


def _box_pixel_window(
    view: View, center: np.ndarray, half: np.ndarray, rot: np.ndarray
) -> tuple[int, int, int, int] | None:
    """Pixel rectangle (u0, u1, v0, v1) a box can cover; the whole image if it straddles the camera plane."""
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], float)
    corners = center + (signs * half) @ rot.T
    cam = (corners - view.layout_from_cam_t) @ view.layout_from_cam_R
    if np.all(cam[:, 2] < 0.05):
        return None
    if np.any(cam[:, 2] < 0.05):
        return 0, view.width_px, 0, view.height_px
    uv = (cam @ view.K.T)[:, :2] / cam[:, 2:3]
    u0, v0 = np.floor(uv.min(axis=0)).astype(int)
    u1, v1 = np.ceil(uv.max(axis=0)).astype(int) + 1
    u0, u1 = max(u0, 0), min(u1, view.width_px)
    v0, v1 = max(v0, 0), min(v1, view.height_px)
    if u0 >= u1 or v0 >= v1:
        return None
    return u0, u1, v0, v1


def _box_local_rays(
    boxes: Boxes, i: int, origin: np.ndarray, d: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor]:
    """Ray origin and directions in box `i`'s own frame."""
    rot = torch.from_numpy(boxes.rotation[i].astype(np.float32))
    o_local = torch.from_numpy(((origin - boxes.center[i]) @ boxes.rotation[i]).astype(np.float32))
    return o_local, d @ rot


def _zbuffer_boxes(
    view: View,
    boxes: Boxes,
    origin: np.ndarray,
    dirs: torch.Tensor,
    depth: torch.Tensor,
    box_id: torch.Tensor,
    face_axis: torch.Tensor,
) -> None:
    """Slab-test each box against the rays in its pixel window; keep the nearest hit per pixel."""
    for i in range(len(boxes)):
        window = _box_pixel_window(view, boxes.center[i], boxes.half[i], boxes.rotation[i])
        if window is None:
            continue
        u0, u1, v0, v1 = window
        idx = (torch.arange(v0, v1)[:, None] * view.width_px + torch.arange(u0, u1)[None, :]).reshape(-1)
        half = torch.from_numpy(boxes.half[i].astype(np.float32))
        o_local, d_local = _box_local_rays(boxes, i, origin, dirs[idx])
        safe = torch.where(d_local.abs() < 1e-9, torch.full_like(d_local, 1e-9), d_local)
        t1 = (-half - o_local) / safe
        t2 = (half - o_local) / safe
        t_near = torch.minimum(t1, t2).max(dim=1)
        t_far = torch.maximum(t1, t2).min(dim=1).values
        wins = (t_near.values <= t_far) & (t_near.values > 0.05) & (t_near.values < depth[idx])
        sel = idx[wins]
        depth[sel] = t_near.values[wins]
        box_id[sel] = i
        face_axis[sel] = t_near.indices[wins]


def _shade_boxes(
    world: World,
    boxes: Boxes,
    ids: torch.Tensor,
    origin: np.ndarray,
    d: torch.Tensor,
    t: torch.Tensor,
    axis: torch.Tensor,
    focal: float,
    sel: torch.Tensor,
    rgb: torch.Tensor,
    semantic: torch.Tensor,
) -> None:
    """Colour and label of the pixels whose nearest surface is a box (`ids`: the box per pixel), batched."""
    rot = torch.from_numpy(boxes.rotation.astype(np.float32))[ids]  # (N, 3, 3) layout_from_box
    center = torch.from_numpy(boxes.center.astype(np.float32))[ids]
    half = torch.from_numpy(boxes.half.astype(np.float32))[ids]
    kind = torch.from_numpy(boxes.kind)[ids]
    hit = torch.from_numpy(origin.astype(np.float32)) + t[:, None] * d
    p_local = torch.einsum("nji,nj->ni", rot, hit - center)
    d_local = torch.einsum("nji,nj->ni", rot, d)
    rows = torch.arange(sel.shape[0])
    normal_local = torch.zeros_like(p_local)
    normal_local[rows, axis] = -torch.sign(d_local[rows, axis])
    is_top = axis == 2
    u = torch.where(axis == 0, p_local[:, 1], p_local[:, 0])
    u = torch.where(is_top, p_local[:, 0] + p_local[:, 1] * 0.37, u) + 17.0 * ids.float()
    height = p_local[:, 2] + half[:, 2]
    base = torch.from_numpy(boxes.color.astype(np.float32))[ids]
    albedo = box_color(kind, base, world.noise, u, height, 2 * half[:, 2], is_top, t / focal)
    normal = torch.einsum("nij,nj->ni", rot, normal_local)
    lambert = (normal @ world.sun).clamp(min=0.0)
    rgb[sel] = albedo * (0.45 + 0.55 * lambert)[:, None]
    labels = torch.tensor([int(_BOX_LABEL[k]) for k in BoxKind], dtype=torch.uint8)
    semantic[sel] = labels[kind]
