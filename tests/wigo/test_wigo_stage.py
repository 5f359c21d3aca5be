"""The WIGO stage and `cama wigo` on the tiny synthetic site: outputs, reruns, errors."""

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from cama_pipeline.data import load_dataset
from cama_pipeline.evaluate.inputs import load_true_poses
from cama_pipeline.wigo import WigoConfig, run
from cama_pipeline.wigo.io import read_wigo
from cama_pipeline.workspace import Workspace
from cama_studio.cli import app

runner = CliRunner()


def test_run_writes_a_pose_per_image_and_skips_up_to_date_scenes(site_root: Path, tmp_path: Path) -> None:
    root = site_root / "nuscenes"
    dataset = load_dataset(root, check_files=False)
    result = run(WigoConfig(), root, tmp_path, show_progress=False)
    assert result.skipped == ()
    truth = load_true_poses(site_root / "ground_truth" / "poses.json")
    for scene in dataset.scenes:
        wigo = read_wigo(result.paths[scene.name])
        assert result.item(scene.name).report == wigo.report
        tokens = [p.token for p in wigo.poses]
        assert sorted(tokens) == sorted(im.token for im in scene.all_images())
        assert [p.timestamp_us for p in wigo.poses] == sorted(p.timestamp_us for p in wigo.poses)
        error = [np.linalg.norm(p.translation - truth[p.token].translation) for p in wigo.poses]
        assert max(error) < 1.0, scene.name
        assert all(p.covariance is not None and p.covariance.shape == (6, 6) for p in wigo.poses)
    again = run(WigoConfig(), root, tmp_path, show_progress=False)
    assert set(again.skipped) == {s.name for s in dataset.scenes}
    assert again.item("scene-0001").report == result.item("scene-0001").report
    forced = run(WigoConfig(), root, tmp_path, scenes=["scene-0001"], overwrite=True, show_progress=False)
    assert forced.skipped == ()
    changed = run(
        WigoConfig(gnss_robust="cauchy"), root, tmp_path, scenes=["scene-0001"], show_progress=False
    )
    assert changed.skipped == ()
    assert read_wigo(changed.paths["scene-0001"]).config["gnss_robust"] == "cauchy"


def test_a_code_change_makes_outputs_stale(
    site_root: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    root = site_root / "nuscenes"
    run(WigoConfig(), root, tmp_path, scenes=["scene-0001"], show_progress=False)
    assert run(WigoConfig(), root, tmp_path, scenes=["scene-0001"], show_progress=False).skipped
    monkeypatch.setattr("cama_pipeline.wigo.stage.code_version", lambda package: f"{package} edited")
    assert run(WigoConfig(), root, tmp_path, scenes=["scene-0001"], show_progress=False).skipped == ()


def test_unknown_scene_is_named(site_root: Path, tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="scene-9999"):
        run(WigoConfig(), site_root / "nuscenes", tmp_path, scenes=["scene-9999"], show_progress=False)


def test_default_workspace_sits_beside_the_dataset(tmp_path: Path) -> None:
    expected = (tmp_path / "site" / "workspace").absolute()
    assert Workspace.for_dataset(tmp_path / "site" / "nuscenes").root == expected


def test_cli_wigo_runs_and_reports_bad_input(site_root: Path, tmp_path: Path) -> None:
    args = ["wigo", str(site_root / "nuscenes"), "--workspace", str(tmp_path), "--robust", "cauchy"]
    result = runner.invoke(app, [*args, "--no-logged-pose"])
    assert result.exit_code == 0, result.output
    assert "scene(s) fused" in result.output
    written = json.loads(Workspace(tmp_path).wigo("scene-0001").read_text())
    assert written["schema"] == "cama.wigo/1"
    assert written["config"]["gnss_robust"] == "cauchy" and written["config"]["logged_pose_sigmas"] == [
        0,
        0,
        0,
        0,
    ]
    missing = runner.invoke(app, ["wigo", str(tmp_path / "nowhere"), "--workspace", str(tmp_path)])
    assert missing.exit_code == 2 and "error" in missing.output
    bad_kernel = runner.invoke(
        app, ["wigo", str(site_root / "nuscenes"), "--workspace", str(tmp_path), "--robust", "tukey"]
    )
    assert bad_kernel.exit_code == 2 and "gnss_robust" in bad_kernel.output


def test_data_set_without_gnss_or_imu_files_degrades(site_root: Path, tmp_path: Path) -> None:
    # the stage reads tables and CAN files only, so a copy without the images is enough
    root = tmp_path / "nuscenes"
    shutil.copytree(site_root / "nuscenes" / "v1.0-synth", root / "v1.0-synth")
    shutil.copytree(site_root / "nuscenes" / "can_bus", root / "can_bus")
    (root / "can_bus" / "scene-0001_gnss.json").unlink()
    (root / "can_bus" / "scene-0002_ms_imu.json").unlink()
    (root / "can_bus" / "scene-0003_zoe_veh_info.json").unlink()
    workspace = tmp_path / "ws"
    with pytest.raises(ValueError, match="scene-0003.*zoe_veh_info"):
        run(WigoConfig(without_wheels="refuse"), root, workspace, show_progress=False)
    result = run(WigoConfig(), root, workspace, show_progress=False)
    assert any("no GNSS" in d for d in read_wigo(result.paths["scene-0001"]).report["degraded"])
    assert any("no IMU" in d for d in read_wigo(result.paths["scene-0002"]).report["degraded"])
    assert any("no wheel speeds" in d for d in read_wigo(result.paths["scene-0003"]).report["degraded"])
