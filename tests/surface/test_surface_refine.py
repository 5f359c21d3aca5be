"""The multi-view refinement of the road elevation against scenes rendered from a known plane."""

import math
from dataclasses import dataclass, replace

import numpy as np
import pytest
import torch

from cama_pipeline.cameras import CameraView
from cama_pipeline.semantics import Semantic
from cama_pipeline.surface.config import RefineConfig, SurfaceConfig
from cama_pipeline.surface.elevation import new_elevation_mlp
from cama_pipeline.surface.grid import SurfaceGrid
from cama_pipeline.surface.observe import Camera
from cama_pipeline.surface.optimise import Mesh, new_mesh
from cama_pipeline.surface.refine import (
    downsampled,
    inner_road,
    refine_elevation,
    refine_steps,
    smooth_residual,
)

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


def refined_heights(painted: bool, start_m: float, config: SurfaceConfig = CONFIG) -> tuple[np.ndarray, Mesh]:
    views, dataset = scene(painted)
    mesh = mesh_at(start_m, config)
    done: list[int] = []
    refine_elevation(mesh, dataset, views, config, lambda images, loss: done.append(images))  # type: ignore[arg-type]
    assert sum(done) == refine_steps(len(views), config)
    with torch.no_grad():
        return mesh.control.at_vertices(mesh.control_heights()).numpy().reshape(121, 121), mesh


def test_a_painted_plane_seen_four_centimetres_too_high_is_brought_down_to_it() -> None:
    heights, _ = refined_heights(painted=True, start_m=0.04)
    middle = heights[20:101, 20:101]  # the patch's middle, which every side's cameras see
    assert abs(float(np.median(middle))) < 0.008
    assert float(np.percentile(np.abs(middle), 90)) < 0.02  # from 0.04 everywhere


def test_bare_asphalt_gives_no_evidence_and_the_surface_stays_where_it_was() -> None:
    heights, mesh = refined_heights(painted=False, start_m=0.04)
    assert float(mesh.offset.abs().max()) < 1e-3  # a millimetre, against the 4 cm of the painted plane
    np.testing.assert_allclose(heights, 0.04, atol=1e-3)


def test_refinement_off_changes_nothing_and_takes_no_image() -> None:
    config = replace(CONFIG, refine=RefineConfig(enabled=False))
    heights, mesh = refined_heights(painted=True, start_m=0.04, config=config)
    assert refine_steps(8, config) == 0
    assert float(mesh.offset.abs().max()) == 0.0


def test_smooth_residual_follows_confident_points_and_decays_to_zero_without_them() -> None:
    best = np.zeros((15, 15))
    confidence = np.zeros((15, 15))
    best[5:10, 5:10] = 0.03
    confidence[5:10, 5:10] = 1.0
    residual = smooth_residual(best, confidence, smoothness=1.0, ridge=0.03)
    assert residual[7, 7] == pytest.approx(0.03, abs=0.003)
    assert abs(residual[0, 0]) < abs(residual[7, 7]) / 3
    np.testing.assert_array_equal(smooth_residual(best, np.zeros_like(best), 1.0, 0.03), 0.0)


def test_a_downsampled_camera_projects_onto_the_pooled_pixel_grid() -> None:
    camera = Camera.of(oblique_camera("c", 0.0, 0.0, 0.0), torch.device("cpu"))
    half = downsampled(camera, 2)
    point = torch.tensor([[5.0, 0.3, 0.0]], dtype=torch.float64)
    uv, _, _ = camera.project(point)
    uv_half, _, _ = half.project(point)
    np.testing.assert_allclose(uv_half.numpy(), (uv.numpy() + 0.5) / 2 - 0.5, atol=1e-4)
    assert (half.width, half.height) == (WIDTH // 2, HEIGHT // 2)


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("sweeps", ()),
        ("sweeps", ((0.02, 0.05),)),
        ("sweeps", ((0.06, 0.0),)),
        ("downsample", 0),
        ("vertex_stride", 0),
        ("semantic_weight", -1.0),
        ("smoothness_weight", -1.0),
        ("ridge_weight", 0.0),
    ],
)
def test_bad_refine_settings_are_named(field: str, value: object) -> None:
    with pytest.raises(ValueError, match=f"RefineConfig.{field}"):
        RefineConfig(**{field: value})  # type: ignore[arg-type]


def test_road_vertices_near_a_kerb_or_the_unseen_are_left_out_of_the_sweep() -> None:
    config = replace(CONFIG, refine=RefineConfig(vertex_stride=1, edge_margin_m=0.3))
    rows, cols = (a.ravel() for a in np.mgrid[0:10, 0:20])
    road = cols < 15  # a kerb from column 15 on
    road[(rows == 5) & (cols == 3)] = False  # one vertex seen once
    inner = inner_road(rows, cols, road, config)
    distance_to_kerb = 15 - cols
    assert not inner[road & (distance_to_kerb <= 3)].any()
    assert not inner[
        (np.abs(rows - 5) <= 3) & (np.abs(cols - 3) <= 3) & (np.hypot(rows - 5, cols - 3) <= 3)
    ].any()
    assert inner[(rows == 5) & (cols == 10)].all() and not inner[~road].any()
    edge = rows == 0  # beyond the grid's first row nothing is known either
    assert not inner[edge].any()
    assert np.array_equal(
        inner_road(
            rows, cols, road, replace(CONFIG, refine=RefineConfig(vertex_stride=1, edge_margin_m=0.0))
        ),
        road,
    )


class RecordingProgress:
    """Records the descriptions a phase's progress bar is given."""

    def __init__(self) -> None:
        self.descriptions: list[str] = []

    def add_task(self, description: str, total: int) -> int:
        self.descriptions.append(description)
        return 0

    def update(self, task: int, **fields: object) -> None:
        if "description" in fields:
            self.descriptions.append(str(fields["description"]))


def test_a_phase_without_a_loss_shows_none_and_one_with_a_loss_shows_it() -> None:
    from cama_pipeline.surface.stage import _Phases

    progress = RecordingProgress()
    phases = _Phases(progress, "site-001")  # type: ignore[arg-type]
    with phases.phase("refine", 2) as advance:
        advance(2, math.nan)
    with phases.phase("elevation", 1) as advance:
        advance(1, 0.25)
    assert (
        "site-001 refine" in progress.descriptions
        and "site-001 elevation loss 0.2500" in progress.descriptions
    )
    assert not any("nan" in d or "refine loss" in d for d in progress.descriptions)
    assert set(phases.seconds) == {"refine", "elevation"}
