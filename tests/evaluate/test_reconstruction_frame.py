"""The frame a reconstruction sits in: the 2D similarity from the true to the reconstruction's keyframe positions,
found on a known similarity, on the tiny site's `cama run`, and refused with a clear error without a surface."""

from pathlib import Path

import numpy as np
import pytest

import bench.annotator as annotator_bench
from cama_pipeline.evaluate.frame import FrameError, ReconstructionFrame, fitted_frame, reconstruction_frame
from cama_pipeline.site.io import read_site_ids
from cama_pipeline.surface.outputs import read_report
from cama_pipeline.workspace import Workspace
from cama_studio.pipeline import PipelineResult
from tests.conftest import GeneratedSite


def test_a_known_similarity_is_found_with_its_shift_and_residual() -> None:
    rng = np.random.default_rng(0)
    world = rng.uniform(-40, 40, size=(50, 2)) + [1000.0, 2000.0]
    truth = ReconstructionFrame(1.004, np.radians(0.1), (0.25, -0.15), "sfm", 50, 0.0, 0.0)
    reconstruction = truth.apply(world) + rng.normal(0, 0.01, size=world.shape)
    frame = fitted_frame(world, reconstruction, "sfm")
    assert frame.scale == pytest.approx(1.004, abs=2e-4)
    assert frame.rotation_rad == pytest.approx(np.radians(0.1), abs=2e-4)
    assert frame.keyframes == 50 and frame.poses == "sfm"
    assert frame.residual_m == pytest.approx(0.0125, abs=0.005)  # the noise is all that is left
    moved = np.linalg.norm(truth.apply(world) - world, axis=1).mean()
    assert frame.shift_m == pytest.approx(moved, abs=0.01) and frame.shift_m > 1.0  # 0.4 % of ~2.2 km
    with_z = np.column_stack([world, np.full(len(world), 31.5)])
    assert np.allclose(frame.apply(with_z), frame.apply(world))  # z plays no part
    np.testing.assert_allclose(frame.world_of(frame.apply(world)), world, atol=1e-9)  # and back
    figures = frame.as_dict()
    assert figures["scale_error_permille"] == pytest.approx(4.0, abs=0.2)
    assert figures["shift_cm"] == pytest.approx(frame.shift_m * 100)


def test_too_few_keyframes_are_refused() -> None:
    with pytest.raises(FrameError, match="2 keyframes posed by both the truth and sfm: at least 3"):
        fitted_frame(np.zeros((2, 2)), np.zeros((2, 2)), "sfm")


def test_the_tiny_site_reconstruction_frame(tiny_site: GeneratedSite, whole_path: PipelineResult) -> None:
    workspace = Workspace(whole_path.workspace)
    (site_id,) = read_site_ids(workspace.sites_index())
    frame = reconstruction_frame(tiny_site.result.out_dir / "nuscenes", workspace, site_id)
    assert frame.poses == read_report(workspace.surface_report(site_id))["poses"]
    assert frame.keyframes >= 3
    assert frame.residual_m < 0.1  # consistent inside, whatever the gauge
    assert frame.residual_m <= frame.shift_m + 1e-9 or frame.shift_m < 0.01
    assert abs(frame.scale - 1.0) < 0.02
    site = tiny_site.result.out_dir  # the annotator bench finds the frame from the rasters it is given
    assert annotator_bench.frame_of(site, workspace.surface_bev(site_id)) == frame
    assert annotator_bench.frame_of(site, site / "ground_truth" / "bev") is None  # not a surface's rasters


def test_a_workspace_without_a_surface_is_a_clear_error(tiny_site: GeneratedSite, tmp_path: Path) -> None:
    with pytest.raises(
        FrameError, match=r"site site-001: no surface report at .*report.json \(run `cama surface` first\)"
    ):
        reconstruction_frame(tiny_site.result.out_dir / "nuscenes", Workspace(tmp_path), "site-001")
