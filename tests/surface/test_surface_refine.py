"""The multi-view refinement of the road elevation against scenes rendered from a known plane."""

import math
from dataclasses import replace

import numpy as np
import pytest
import torch

from cama_pipeline.surface.config import RefineConfig, SurfaceConfig
from cama_pipeline.surface.observe import Camera
from cama_pipeline.surface.optimise import Mesh
from cama_pipeline.surface.refine import (
    downsampled,
    inner_road,
    refine_elevation,
    refine_steps,
    smooth_residual,
)
from tests.surface.painted_plane import CONFIG, HEIGHT, WIDTH, mesh_at, oblique_camera, scene


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
