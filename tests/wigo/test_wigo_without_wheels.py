"""A scene without wheel speeds (nuScenes' CAN bus expansion leaves some out): WIGO passes its logged ego poses
through with the logged pose's sigmas as covariance, says so in the report and on the command line, and the
other scenes fuse as before; `without_wheels = "refuse"` names the scene instead."""

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from cama_pipeline.data import load_dataset
from cama_pipeline.data.schema import CAN_DIR, WHEEL_MESSAGE, can_file_name
from cama_pipeline.wigo import WigoConfig, run
from cama_pipeline.wigo.fusion import FLAT_HEIGHT_GAUGE_SIGMA_M, NoGlobalConstraint
from cama_pipeline.wigo.inputs import NoWheelSpeeds, logged_poses
from cama_pipeline.wigo.io import read_wigo
from cama_pipeline.wigo.logged_only import NO_ODOMETRY, logged_pose_clip
from cama_studio.cli import app

SCENE = "scene-0001"


@pytest.fixture
def root(site_root: Path, tmp_path: Path) -> Path:
    """A copy of the tiny site's tables and CAN files (all WIGO reads) without the first scene's wheel speeds."""
    root = tmp_path / "nuscenes"
    version = next(p for p in (site_root / "nuscenes").iterdir() if (p / "scene.json").is_file())
    shutil.copytree(version, root / version.name)
    shutil.copytree(site_root / "nuscenes" / CAN_DIR, root / CAN_DIR)
    (root / CAN_DIR / can_file_name(SCENE, WHEEL_MESSAGE)).unlink()
    return root


def test_the_logged_poses_pass_through_and_the_rest_fuse(root: Path, tmp_path: Path) -> None:
    result = run(WigoConfig(), root, tmp_path / "ws", show_progress=False)
    dataset = load_dataset(root, check_files=False)
    scene = next(s for s in dataset.scenes if s.name == SCENE)
    wigo = read_wigo(result.paths[SCENE])
    assert wigo.report["odometry"] == NO_ODOMETRY and wigo.report["global_constraint"] == "logged_pose"
    by_token = {image.token: image for image in scene.all_images()}
    assert sorted(p.token for p in wigo.poses) == sorted(by_token)
    for pose in wigo.poses:
        np.testing.assert_allclose(
            pose.translation, by_token[pose.token].global_from_ego.translation, atol=1e-9
        )
        assert pose.covariance is not None and np.isfinite(pose.covariance).all()
    sigmas = np.sqrt(np.diag(wigo.poses[0].covariance))
    horizontal, vertical, _, _ = WigoConfig().logged_pose_sigmas
    np.testing.assert_allclose(sigmas[3:], [horizontal, horizontal, vertical])
    others = [name for name in result.paths if name != SCENE]
    assert others and all("odometry" not in read_wigo(result.paths[n]).report for n in others)


def test_refuse_names_the_scene_and_the_message(root: Path, tmp_path: Path) -> None:
    with pytest.raises(NoWheelSpeeds, match=f"{SCENE}.*{WHEEL_MESSAGE}"):
        run(WigoConfig(without_wheels="refuse"), root, tmp_path / "ws", scenes=[SCENE], show_progress=False)
    assert not (tmp_path / "ws" / "wigo" / f"{SCENE}.json").exists()


def test_a_2d_localization_leaves_the_height_loose(root: Path) -> None:
    scene = next(s for s in load_dataset(root, check_files=False).scenes if s.name == SCENE)
    cameras = logged_poses(scene)
    flat = type(cameras)(
        cameras.tokens, cameras.channels, cameras.times_us, cameras.rotation, cameras.translation * [1, 1, 0]
    )
    fused = logged_pose_clip(SCENE, flat, WigoConfig())
    assert fused.report["logged_pose_height"].startswith("free")
    assert np.sqrt(fused.covariance[0, 5, 5]) == pytest.approx(FLAT_HEIGHT_GAUGE_SIGMA_M)
    with pytest.raises(NoGlobalConstraint, match=SCENE):
        logged_pose_clip(SCENE, cameras, WigoConfig(logged_pose_sigmas=(0.0, 0.0, 0.0, 0.0)))


def test_the_command_lists_the_scenes_passed_through(root: Path, tmp_path: Path) -> None:
    result = CliRunner().invoke(app, ["wigo", str(root), "--workspace", str(tmp_path / "ws")])
    assert result.exit_code == 0, result.output
    assert "no wheel speeds" in result.output and SCENE in result.output
    saved = json.loads((tmp_path / "ws" / "wigo" / f"{SCENE}.json").read_text())
    assert saved["report"]["odometry"] == NO_ODOMETRY


def test_the_option_must_be_known() -> None:
    with pytest.raises(ValueError, match="without_wheels must be logged_pose or refuse"):
        WigoConfig(without_wheels="skip")  # type: ignore[arg-type]
