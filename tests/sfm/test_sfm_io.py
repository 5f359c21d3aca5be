"""The sfm workspace format: poses and points round-trip; missing or malformed files give clear errors."""

import json
from pathlib import Path

import numpy as np
import pytest

from cama_pipeline.data import Pose
from cama_pipeline.io import WorkspaceError
from cama_pipeline.sfm.io import (
    PoseEntry,
    SparsePoints,
    read_points,
    read_refined_poses,
    write_points,
    write_poses,
)
from cama_pipeline.workspace import Workspace

SITE = "site-001"


def pose(x: float, yaw_deg: float) -> np.ndarray:
    half = np.radians(yaw_deg) / 2
    return Pose(np.array([x, 2.0, 0.5]), np.array([np.cos(half), 0, 0, np.sin(half)])).matrix()


def write_two(workspace: Path) -> None:
    entries = {
        "tok-a": PoseEntry("samples/CAM_FRONT/a.jpg", "scene-1", "CAM_FRONT", pose(1.0, 30.0), False),
        "tok-b": PoseEntry("samples/CAM_BACK/b.jpg", "scene-1", "CAM_BACK", pose(2.0, -170.0), True),
    }
    write_poses(Workspace(workspace).sfm_poses(SITE), site_id=SITE, digest="x", poses=entries)


def test_poses_round_trip_and_flagged_left_out_by_default(tmp_path: Path) -> None:
    write_two(tmp_path)
    poses = read_refined_poses(Workspace(tmp_path).sfm_poses(SITE))
    assert set(poses) == {"tok-a"}
    np.testing.assert_allclose(poses["tok-a"], pose(1.0, 30.0), atol=1e-12)
    everything = read_refined_poses(Workspace(tmp_path).sfm_poses(SITE), include_flagged=True)
    np.testing.assert_allclose(everything["tok-b"], pose(2.0, -170.0), atol=1e-12)


def test_points_round_trip(tmp_path: Path) -> None:
    points = SparsePoints(np.arange(12.0).reshape(4, 3), np.array([0, 1, 3, 4]), np.ones(4), np.full(4, 3))
    write_points(Workspace(tmp_path).sfm_points(SITE), points)
    back = read_points(Workspace(tmp_path).sfm_points(SITE))
    np.testing.assert_array_equal(back.xyz, points.xyz)
    assert back.label.dtype == np.uint8 and back.label.tolist() == [0, 1, 3, 4]
    assert back.track_length.tolist() == [3, 3, 3, 3]


def test_missing_outputs_name_the_file_and_the_command(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match=r"poses\.json.*cama sfm"):
        read_refined_poses(Workspace(tmp_path).sfm_poses(SITE))
    with pytest.raises(FileNotFoundError, match=r"points\.npz.*cama sfm"):
        read_points(Workspace(tmp_path).sfm_points(SITE))


def test_malformed_poses_name_the_file_and_field(tmp_path: Path) -> None:
    write_two(tmp_path)
    path = Workspace(tmp_path).sfm_poses(SITE)
    data = json.loads(path.read_text())
    data["images"]["tok-a"]["translation"] = [1.0, "two"]
    path.write_text(json.dumps(data))
    with pytest.raises(WorkspaceError, match=r"poses\.json.*tok-a.*translation"):
        read_refined_poses(Workspace(tmp_path).sfm_poses(SITE))
    path.write_text("{not json")
    with pytest.raises(WorkspaceError, match=r"poses\.json.*not valid JSON"):
        read_refined_poses(Workspace(tmp_path).sfm_poses(SITE))


def test_malformed_points_name_the_file(tmp_path: Path) -> None:
    path = Workspace(tmp_path).sfm_points(SITE)
    path.parent.mkdir(parents=True)
    np.savez(
        path, xyz=np.zeros((3, 3)), label=np.zeros(2, np.uint8), error_px=np.zeros(3), track_length=np.ones(3)
    )
    with pytest.raises(WorkspaceError, match=r"points\.npz.*label"):
        read_points(Workspace(tmp_path).sfm_points(SITE))
    np.savez(path, xyz=np.zeros((3, 3)))
    with pytest.raises(WorkspaceError, match=r"points\.npz.*missing"):
        read_points(Workspace(tmp_path).sfm_points(SITE))
