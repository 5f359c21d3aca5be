"""Reading and writing the workspace files: round trips and errors that name the file and field."""

import json
from pathlib import Path

import numpy as np
import pytest

from cama_pipeline.io import WorkspaceError
from cama_pipeline.keyframes.io import FrameRecord, KeyframesFile, read_keyframes, write_keyframes
from cama_pipeline.site.io import read_sites_index
from cama_pipeline.wigo.io import PoseRecord, WigoFile, read_wigo, write_wigo


def _wigo() -> WigoFile:
    pose = PoseRecord("tok", "CAM_FRONT", 5, np.array([1.0, 2.0, 3.0]), np.array([1.0, 0, 0, 0]), np.eye(6))
    nan_pose = PoseRecord(
        "tok2", "CAM_BACK", 6, np.zeros(3), np.array([0.0, 0, 0, 1]), np.full((6, 6), np.nan)
    )
    return WigoFile("scene-1", "st", "fp", {"a": 1}, {"nodes": 2}, [1, 2], (pose, nan_pose))


def test_wigo_file_round_trip(tmp_path: Path) -> None:
    path = tmp_path / "w.json"
    write_wigo(path, _wigo())
    back = read_wigo(path)
    assert back.scene == "scene-1" and back.fingerprint == "fp"
    assert np.allclose(back.poses[0].translation, [1, 2, 3]) and np.allclose(
        back.poses[0].covariance, np.eye(6)
    )
    assert back.poses[1].covariance is None  # NaN covariances are stored as null


def test_keyframes_file_round_trip(tmp_path: Path) -> None:
    frame = FrameRecord(0, 10, {"CAM_FRONT": "a"}, 0, True, "first")
    path = tmp_path / "k.json"
    write_keyframes(path, KeyframesFile("s", "fp", {}, False, 3.0, 0, 0, (frame,)))
    assert read_keyframes(path).keyframes == (frame,)


def test_missing_file_says_which_command_writes_it(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="cama wigo"):
        read_wigo(tmp_path / "none.json")
    with pytest.raises(FileNotFoundError, match="cama sites"):
        read_sites_index(tmp_path / "none.json")


@pytest.mark.parametrize(
    ("content", "message"),
    [
        ("{", "not valid JSON"),
        (json.dumps({"schema": "other"}), "'schema'"),
        (json.dumps({"schema": "cama.wigo/1", "scene": "s"}), "'poses'"),
        (json.dumps({"schema": "cama.wigo/1", "poses": [{"token": "t"}]}), "poses\\[0\\].'translation'"),
    ],
)
def test_bad_wigo_file_names_the_field(tmp_path: Path, content: str, message: str) -> None:
    path = tmp_path / "bad.json"
    path.write_text(content)
    with pytest.raises(WorkspaceError, match=message):
        read_wigo(path)
