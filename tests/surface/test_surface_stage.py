"""`cama surface` on the tiny site: outputs in the ground-truth raster format, unobserved cells marked, reruns
skip, a site without road points and a bad pose source give clear errors, the CLI runs."""

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import trimesh
from typer.testing import CliRunner

from cama_pipeline.bev import read_layer
from cama_pipeline.data import load_dataset
from cama_pipeline.results import ItemResult
from cama_pipeline.semantics import ROAD_SURFACE_IDS, Semantic
from cama_pipeline.sfm.io import SparsePoints, write_points
from cama_pipeline.site.io import read_site_ids, read_site_manifest
from cama_pipeline.surface import SurfaceConfig, run
from cama_pipeline.surface.outputs import read_kerb_step
from cama_pipeline.surface.points import NoRoadPointsError, ego_poses, trajectory_strip
from cama_pipeline.surface.poses import posed_views
from cama_pipeline.surface.steps import step_summary
from cama_pipeline.workspace import Workspace
from cama_studio.cli import app
from models.vma.rasters import load_site_rasters
from tests.pairs.site_workspace import build_site_workspace

FAST = SurfaceConfig(
    resolution_m=0.5, region_radius_m=12.0, elevation_iterations=150, epochs=1, images_per_batch=8
)


@pytest.fixture(scope="module")
def dataset_root(tiny_site) -> Path:  # type: ignore[no-untyped-def]
    return tiny_site.result.dataset_root


@pytest.fixture(scope="module")
def workspace(dataset_root: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    return build_site_workspace(dataset_root, tmp_path_factory.mktemp("surface-ws"))


@pytest.fixture(scope="module")
def surface(dataset_root: Path, workspace: Path) -> ItemResult:
    return run(FAST, dataset_root, workspace, poses="ground_truth", show_progress=False).items[0]


def test_rasters_have_the_ground_truth_format_and_load_for_proposals(surface: ItemResult, tiny_site) -> None:  # type: ignore[no-untyped-def]
    bev = surface.path / "bev"
    truth = tiny_site.result.ground_truth_dir / "bev"
    assert sorted(p.name for p in bev.iterdir()) == sorted(p.name for p in truth.iterdir())
    geo, true_geo = (json.loads((f / "georeference.json").read_text()) for f in (bev, truth))
    assert geo.keys() == true_geo.keys() and geo["resolution"] == 0.5
    rasters = load_site_rasters(bev)
    assert rasters.shape == (geo["height"], geo["width"])
    assert np.load(bev / "elevation.npy").dtype == np.float32
    observed = rasters.semantic != int(Semantic.UNOBSERVED)
    assert observed.any() and (~observed).any()
    assert set(np.unique(rasters.semantic[observed])) <= {0, 1, 2, 3, 4}
    assert np.mean(rasters.semantic[observed] == int(Semantic.ROAD)) > 0.3


def test_unobserved_cells_are_255_nan_black_and_zero_rays(surface: ItemResult) -> None:
    import cv2

    bev = surface.path / "bev"
    semantic = cv2.imread(str(bev / "semantic.png"), cv2.IMREAD_UNCHANGED)
    count = cv2.imread(str(bev / "observation_count.png"), cv2.IMREAD_UNCHANGED)
    photometric = cv2.imread(str(bev / "photometric.png"), cv2.IMREAD_COLOR)
    elevation = np.load(bev / "elevation.npy")
    assert count.dtype == np.uint16
    unobserved = semantic == int(Semantic.UNOBSERVED)
    np.testing.assert_array_equal(unobserved, count == 0)
    np.testing.assert_array_equal(unobserved, np.isnan(elevation))
    assert np.all(photometric[unobserved] == 0)


def test_mesh_and_report(surface: ItemResult) -> None:
    mesh = trimesh.load(surface.path / "mesh.ply", process=False)
    report = surface.report
    assert len(mesh.vertices) == report["cells_observed"] and len(mesh.faces) > 0
    assert mesh.visual.vertex_colors.shape == (len(mesh.vertices), 4)
    assert np.all(mesh.face_normals[:, 2] > 0.5)  # upward, the road seen from above
    assert set(report["seconds"]) == {"elevation", "refine", "observe", "joint", "optimise", "export"}
    assert report["losses"]["joint"] == []  # off by default
    sweeps = report["losses"]["refine"]
    assert [sweep["step_m"] for sweep in sweeps] == [step for _, step in report["config"]["refine"]["sweeps"]]
    assert all(sweep["control_points_constrained"] > 0 for sweep in sweeps)
    assert report["points"]["strip"] > 0 and report["points"]["sfm"] == 0
    assert report["points"]["sfm_frame_is_the_poses"] is True  # no SfM points at all
    assert report["losses"]["epochs"] and report["losses"]["elevation"][-1] < report["losses"]["elevation"][0]
    weak = report["weak_observation"]
    count = read_layer(surface.path / "bev", "observation_count")
    assert weak["observed_cells"] == report["cells_observed"] == int((count > 0).sum())
    assert weak["weak_cells"] == int(((count > 0) & (count < weak["weak_rays"])).sum())
    assert 0 <= weak["road_weak_share"] <= 1 and weak["weak_regions"] == len(weak["regions"])
    extrapolated = report[
        "extrapolated_heights"
    ]  # the fitted points are the strip's alone here (no SfM points)
    assert extrapolated["road_cells"] == weak["road_cells"]
    assert 0 < extrapolated["extrapolated_road_cells"] < extrapolated["road_cells"]
    assert extrapolated["farthest_m"] > extrapolated["height_support_m"]


def test_elevation_matches_the_true_road_under_the_trajectory(
    surface: ItemResult,
    tiny_site,
    dataset_root: Path,
    workspace: Path,  # type: ignore[no-untyped-def]
) -> None:
    ws = Workspace(workspace)
    manifest = read_site_manifest(ws.site_manifest(surface.name))
    views = posed_views(load_dataset(dataset_root), manifest, ws, surface.name, "ground_truth")
    under_car = trajectory_strip(ego_poses(views), SurfaceConfig(strip_half_width_m=0.5))
    ours = load_site_rasters(surface.path / "bev")
    elevation = np.load(surface.path / "bev" / "elevation.npy")
    truth_dir = tiny_site.result.ground_truth_dir / "bev"
    truth = load_site_rasters(truth_dir)
    col, row = np.round(ours.pixel_from_global(under_car[:, :2])).astype(int).T
    true_col, true_row = np.round(truth.pixel_from_global(under_car[:, :2])).astype(int).T
    error = elevation[row, col] - np.load(truth_dir / "elevation.npy")[true_row, true_col]
    assert not np.isnan(error).any()
    assert np.median(np.abs(error)) < 0.03


@pytest.fixture(scope="module")
def stepped(dataset_root: Path, tmp_path_factory: pytest.TempPathFactory) -> ItemResult:
    """The surface at 0.1 m, where a kerb is a few cells wide, in a workspace of its own; the kerb step alone,
    without the kerb line (which the test below turns on)."""
    workspace = build_site_workspace(dataset_root, tmp_path_factory.mktemp("stepped-ws"))
    config = replace(FAST, resolution_m=0.1, epochs=0)
    config = replace(config, kerb_step=replace(config.kerb_step, kerb_line=False))
    return run(config, dataset_root, workspace, poses="ground_truth", show_progress=False).items[0]


def test_kerb_steps_stand_where_the_true_sidewalks_are_raised(stepped: ItemResult, tiny_site) -> None:  # type: ignore[no-untyped-def]
    bev = stepped.path / "bev"
    step = read_kerb_step(stepped.path / "kerb_step.npy", read_layer(bev, "semantic").shape)
    semantic, elevation = read_layer(bev, "semantic"), read_layer(bev, "elevation")
    observed = semantic != int(Semantic.UNOBSERVED)
    assert np.array_equal(np.isnan(step), ~observed)
    assert np.allclose(np.unique(step[observed]), [0.0, 0.13])
    assert stepped.report["kerb_step"] == step_summary(semantic, step, 0.13)
    mesh = trimesh.load(stepped.path / "mesh.ply", process=False)
    assert np.allclose(np.sort(mesh.vertices[:, 2]), np.sort((elevation + step)[observed]), atol=1e-5)
    truth_dir = tiny_site.result.ground_truth_dir / "bev"
    ours, truth = load_site_rasters(bev), load_site_rasters(truth_dir)
    rows, cols = np.nonzero(observed)
    xy = ours.global_from_pixel(np.column_stack([cols, rows]))
    true_col, true_row = np.round(truth.pixel_from_global(xy)).astype(int).T
    true_z = np.load(truth_dir / "elevation.npy")[true_row, true_col]
    truly_raised = true_z - elevation[rows, cols] > 0.065
    raised = step[rows, cols] > 0
    # measured 0.50 precision and 0.28 recall on this low-resolution site (256x144 images); raising cells at
    # random would give the base rate, 0.19 (bench/surface.py measures the default and a randomised site)
    assert (raised & truly_raised).sum() > 0.4 * raised.sum()
    assert (raised & truly_raised).sum() > 0.2 * truly_raised.sum()


def test_rerun_skips(surface: ItemResult, dataset_root: Path, workspace: Path) -> None:
    report = Workspace(workspace).surface_report(surface.name)
    before = report.stat().st_mtime_ns
    again = run(FAST, dataset_root, workspace, poses="ground_truth", show_progress=False).items[0]
    assert again.skipped and report.stat().st_mtime_ns == before
    assert again.report["fingerprint"] == surface.report["fingerprint"]


def test_no_road_points_is_a_clear_error(dataset_root: Path, tmp_path: Path, workspace: Path) -> None:
    config = SurfaceConfig(use_trajectory_strip=False, resolution_m=0.5)
    with pytest.raises(NoRoadPointsError, match=r"site .*no road surface points"):
        run(config, dataset_root, workspace, poses="ground_truth", show_progress=False)


def test_sfm_points_on_other_poses_are_named_as_another_frame(
    dataset_root: Path, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    """Built on true poses, a workspace's SfM road points join the fit where SfM placed them: the run says so
    in a warning and in its report (README, "Other pose sources take the SfM points as SfM placed them")."""
    workspace = build_site_workspace(dataset_root, tmp_path / "sfm-points-ws")
    site_id = read_site_ids(Workspace(workspace).sites_index())[0]
    views = posed_views(
        load_dataset(dataset_root),
        read_site_manifest(Workspace(workspace).site_manifest(site_id)),
        Workspace(workspace),
        site_id,
        "ground_truth",
    )
    on_road = trajectory_strip(ego_poses(views)[::4], SurfaceConfig())[::7]
    labels = np.full(len(on_road), int(Semantic.ROAD))
    path = Workspace(workspace).sfm_points(site_id)
    path.parent.mkdir(parents=True)
    write_points(path, SparsePoints(on_road, labels, np.zeros(len(on_road)), np.full(len(on_road), 3)))
    with caplog.at_level("WARNING"):
        item = run(FAST, dataset_root, workspace, poses="ground_truth", show_progress=False).items[0]
    assert item.report["points"]["sfm"] == len(on_road)
    assert item.report["points"]["sfm_frame_is_the_poses"] is False
    assert f"{len(on_road)} SfM road points join the surface on ground_truth poses" in caplog.text


def test_bad_pose_source_is_a_clear_error(dataset_root: Path, workspace: Path) -> None:
    with pytest.raises(ValueError, match="poses must be one of"):
        run(FAST, dataset_root, workspace, poses="lidar", show_progress=False)
    with pytest.raises(FileNotFoundError, match="cama sfm"):
        run(FAST, dataset_root, workspace, poses="sfm", overwrite=True, show_progress=False)


def test_cli_runs_and_reports_bad_input(dataset_root: Path, workspace: Path) -> None:
    runner = CliRunner()
    args = ["surface", str(dataset_root), "--workspace", str(workspace), "--resolution-m", "0.5"]
    result = runner.invoke(app, [*args, "--epochs", "0", "--poses", "wigo"])
    assert result.exit_code == 0, result.output
    assert "site" in result.output and "cells" in result.output
    bad = runner.invoke(app, [*args, "--poses", "lidar"])
    assert bad.exit_code == 2 and "poses must be one of" in bad.output


def test_cli_runs_the_joint_optimisation_when_asked_and_names_bad_passes(
    dataset_root: Path, tmp_path: Path
) -> None:
    workspace = build_site_workspace(dataset_root, tmp_path / "joint-ws")
    runner = CliRunner()
    args = ["surface", str(dataset_root), "--workspace", str(workspace), "--resolution-m", "0.5"]
    result = runner.invoke(app, [*args, "--epochs", "0", "--poses", "ground_truth", "--joint-epochs", "1"])
    assert result.exit_code == 0, result.output
    report = json.loads(next((workspace / "surface").glob("*/report.json")).read_text())
    (joint,) = report["losses"]["joint"]
    assert joint["rays_hitting"] > 0.5 and report["seconds"]["joint"] > 0
    bad = runner.invoke(app, [*args, "--joint-epochs", "-1"])
    assert bad.exit_code == 2 and "JointConfig.epochs" in bad.output


def test_the_kerb_line_raises_road_labelled_kerb_cells_and_reads_them_at_curb_height(
    stepped: ItemResult,
    dataset_root: Path,
    tmp_path_factory: pytest.TempPathFactory,
    tiny_site,  # type: ignore[no-untyped-def]
) -> None:
    workspace = build_site_workspace(dataset_root, tmp_path_factory.mktemp("kerb-line-ws"))
    config = replace(FAST, resolution_m=0.1, epochs=0)
    assert config.kerb_step.kerb_line  # on by default
    lined = run(config, dataset_root, workspace, poses="ground_truth", show_progress=False).items[0]
    before, after = read_layer(stepped.path / "bev", "semantic"), read_layer(lined.path / "bev", "semantic")
    step = read_kerb_step(lined.path / "kerb_step.npy", after.shape)
    road = np.isin(before, ROAD_SURFACE_IDS)
    moved = road & np.isin(after, [int(Semantic.CURB), int(Semantic.BACKGROUND)])
    assert moved.sum() > 100
    assert (step[moved] > 0).all()  # every cell taken off the road stands on the step
    assert not (~road & np.isin(after, ROAD_SURFACE_IDS) & (before != after)).any()  # nothing joins the road
    truth = load_site_rasters(tiny_site.result.ground_truth_dir / "bev")
    ours = load_site_rasters(lined.path / "bev")

    def truly_off_road(cells: np.ndarray) -> np.ndarray:
        rows, cols = np.nonzero(cells)
        xy = ours.global_from_pixel(np.column_stack([cols, rows]))
        true_col, true_row = np.round(truth.pixel_from_global(xy)).astype(int).T
        return ~np.isin(truth.semantic[true_row, true_col], ROAD_SURFACE_IDS)

    # measured 0.40 of the 675 cells taken off the road truly off it, against 0.01 of all road-labelled cells: at
    # 256x144 the masks' blur lowers the road share of the road-level vote just before the kerb too, so the line
    # also takes a road row there (bench/kerb_profile.py measures the default site's 512x288 images)
    assert (
        truly_off_road(moved).mean() > 0.25
        and truly_off_road(moved).mean() > 10 * truly_off_road(road).mean()
    )
