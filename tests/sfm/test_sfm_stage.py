"""`cama sfm` stage on the tiny site: clips in parallel, merged; outputs readable; reruns skip; a clip that
cannot be reconstructed is reported and left out; missing inputs give clear errors."""

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from cama_pipeline.results import StageResult
from cama_pipeline.semantics import Semantic
from cama_pipeline.sfm.baseline import aligned_poses, pose_errors
from cama_pipeline.sfm.config import SfmConfig
from cama_pipeline.sfm.io import read_model, read_points, read_refined_poses, read_report
from cama_pipeline.sfm.stage import run
from cama_pipeline.workspace import Workspace

CONFIG = SfmConfig.preset("rigid")


def copy_workspace(inputs: object, target: Path) -> Path:
    shutil.copytree(inputs.workspace, target)  # type: ignore[attr-defined]
    return target


@pytest.fixture(scope="module")
def first_run(sfm_inputs: object, tmp_path_factory: pytest.TempPathFactory) -> StageResult:
    workspace = copy_workspace(sfm_inputs, tmp_path_factory.mktemp("sfm-stage") / "workspace")
    return run(CONFIG, sfm_inputs.dataset_root, workspace, workers=2, show_progress=False)  # type: ignore[attr-defined]


def gauge_free_error_cm(inputs: object, world_from_ego: dict[str, np.ndarray]) -> float:
    """Mean camera position error (cm) of ego poses by token against the true poses, after the similarity
    that fits them best (the clips inherit their global placement from odometry; their shape is SfM's)."""
    views = {v.token: v for v in inputs.views}  # type: ignore[attr-defined]
    truth = inputs.true_world_from_ego  # type: ignore[attr-defined]
    estimated = {views[t].name: pose @ views[t].ego_from_cam for t, pose in world_from_ego.items()}
    reference = {v.name: truth[v.name] @ v.ego_from_cam for v in views.values()}
    return pose_errors(aligned_poses(estimated, reference), reference).position_cm


@pytest.mark.slow
def test_site_outputs_cover_every_clip_and_image(sfm_inputs: object, first_run: StageResult) -> None:
    (site,) = first_run.items
    workspace, site_id = first_run.workspace, site.name
    report = read_report(workspace.sfm_report(site_id))
    assert site.path == workspace.sfm_dir(site_id) and site.report == report
    assert all(clip["status"] == "ok" for clip in report["clips"].values())
    assert len(report["clips"]) == 2  # the stationary scene rides with the moving one it was merged into
    merged = report["merged"]
    assert merged["registered_images"] >= 0.9 * merged["images"]
    assert merged["gauge"]["poses"] >= 0.9 * merged["images"]  # placed by every clip's odometry poses
    poses = read_refined_poses(workspace.sfm_poses(site_id), include_flagged=True)
    assert set(poses) == {v.token for v in sfm_inputs.views}  # type: ignore[attr-defined]
    points = read_points(workspace.sfm_points(site_id))
    assert len(points.xyz) == merged["points"] == read_model(workspace.sfm_model(site_id)).num_points3D()
    assert Semantic.ROAD in set(points.label.tolist()) and np.all(points.track_length >= 2)
    wigo = gauge_free_error_cm(sfm_inputs, {v.token: v.world_from_ego for v in sfm_inputs.views})  # type: ignore[attr-defined]
    assert gauge_free_error_cm(sfm_inputs, poses) < 0.7 * wigo


@pytest.mark.slow
def test_rerun_skips_up_to_date_sites(sfm_inputs: object, first_run: StageResult) -> None:
    report = first_run.workspace.sfm_report(first_run.items[0].name)
    before = report.stat().st_mtime_ns
    again = run(CONFIG, sfm_inputs.dataset_root, first_run.workspace, show_progress=False)  # type: ignore[attr-defined]
    assert again.items[0].skipped and report.stat().st_mtime_ns == before


@pytest.mark.slow
def test_clip_that_fails_is_reported_and_left_out(sfm_inputs: object, tmp_path: Path) -> None:
    workspace = copy_workspace(sfm_inputs, tmp_path / "workspace")
    manifest_path = Workspace(workspace).site_manifest("site-001")
    manifest = json.loads(manifest_path.read_text())
    failing = next(
        s
        for s in manifest["scenes"]
        if s["kind"] == "moving" and s["scene"] != manifest["scenes"][0]["scene"]
    )
    kept = 0
    for frame in failing["frames"]:  # one keyframe left: nothing to triangulate across time
        kept += bool(frame["keyframe"])
        frame["keyframe"] = bool(frame["keyframe"]) and kept <= 1
    manifest_path.write_text(json.dumps(manifest))
    (site,) = run(CONFIG, sfm_inputs.dataset_root, workspace, show_progress=False).items  # type: ignore[attr-defined]
    clips = site.report["clips"]
    assert clips[failing["scene"]]["status"] == "failed" and clips[failing["scene"]]["error"]
    assert all(c["status"] == "ok" for scene, c in clips.items() if scene != failing["scene"])
    poses_path = Workspace(workspace).sfm_poses("site-001")
    poses = read_refined_poses(poses_path, include_flagged=True)
    scenes = {json.loads(poses_path.read_text())["images"][t]["scene"] for t in poses}
    assert failing["scene"] not in scenes and poses


def test_missing_features_database_names_the_file(sfm_inputs: object, tmp_path: Path) -> None:
    workspace = copy_workspace(sfm_inputs, tmp_path / "workspace")
    shutil.rmtree(Workspace(workspace).stage_dir("features"))
    with pytest.raises(FileNotFoundError, match=r"database\.db.*cama features"):
        run(CONFIG, sfm_inputs.dataset_root, workspace, show_progress=False)  # type: ignore[attr-defined]


def test_refined_poses_on_the_tiny_site(sfm_inputs: object, first_run: StageResult) -> None:
    """The exports' refined poses on real WIGO and SfM outputs: every image SfM posed (unflagged) has exactly its
    SfM pose, every other image of the site's scenes a WIGO pose, corrected where an SfM keyframe is near."""
    from cama_pipeline.data import load_dataset
    from cama_pipeline.refined_poses import refined_poses, site_scenes

    (site,) = first_run.items
    dataset = load_dataset(sfm_inputs.dataset_root)  # type: ignore[attr-defined]
    refined = refined_poses(dataset, first_run.workspace, site.name)
    sfm = read_refined_poses(first_run.workspace.sfm_poses(site.name))
    assert sfm and all(refined[token].source == "sfm" for token in sfm)
    for token, matrix in sfm.items():
        np.testing.assert_allclose(refined[token].global_from_ego.matrix(), matrix, atol=1e-9)
    scenes = set(site_scenes(first_run.workspace, site.name))
    images = [im for scene in dataset.scenes if scene.name in scenes for im in scene.all_images()]
    assert {im.token for im in images} <= set(refined)
    others = [refined[im.token].source for im in images if im.token not in sfm]
    assert set(others) <= {"wigo+sfm", "wigo"} and "wigo+sfm" in others
