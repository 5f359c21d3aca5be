"""`cama export` with refined poses (issue 24.1): SfM poses for the images SfM posed, WIGO corrected by the SfM
keyframes between them, each pose's source recorded; `--poses coarse` writes the logged ones; refined without
the SfM outputs is exit 2 naming the missing file."""

import json
from pathlib import Path

import numpy as np
import pytest
import typer
from typer.testing import CliRunner

from annotations import AnnotationSet, Georeference, MapElement
from annotations.cama_odometry import CAMERA_NAME_FROM_CHANNEL
from annotations.maptr_format import read_maptr
from cama_pipeline.data import CameraImage, Dataset, load_dataset
from cama_pipeline.refined_poses import refined_poses
from cama_pipeline.workspace import Workspace
from cama_studio.export_command import export_command, import_command
from tests.annotations.annotation_helpers import element_kwargs
from tests.annotations.refined_helpers import (
    SITE_ID,
    expected_shift,
    sfm_images,
    sfm_shift,
    shifted,
    write_reconstruction,
)
from tests.data.nuscenes_fixture import write_nuscenes_fixture

app = typer.Typer()
app.command("export")(export_command)
app.command("import")(import_command)
runner = CliRunner()


@pytest.fixture()
def dataset_root(tmp_path: Path) -> Path:
    """The three-sample fixture data set (key frames and one sweep each per camera)."""
    return write_nuscenes_fixture(tmp_path / "nuscenes", n_samples=3, with_can=False, with_lidar=False).root


def _set(tmp_path: Path, georef: Georeference) -> Path:
    element = MapElement.model_validate(element_kwargs(points_2d=[[1.0, 1.0], [5.0, 2.0]]))
    path = tmp_path / "annotations.json"
    AnnotationSet(site_id=SITE_ID, georeference=georef, elements=[element]).write_json(path)
    return path


def _rows(folder: Path, channel: str) -> np.ndarray:
    """A scene folder's clip-mode odometry rows of a channel, translations back in global metres."""
    text = (folder / f"odometry/scmv_{CAMERA_NAME_FROM_CHANNEL[channel]}.txt").read_text()
    assert not text.startswith("#")
    rows = np.array([line.split() for line in text.splitlines()], dtype=float)
    sidecar = json.loads((folder / "maps/georeference.json").read_text())
    rows[:, 1:4] += np.asarray(sidecar["world_origin_global"])
    return rows


def _export_args(
    tmp_path: Path, georef: Georeference, dataset_root: Path, elevation: np.ndarray
) -> list[str]:
    """`cama export` of the one-divider set with a raster (the release's elevation map needs one)."""
    np.save(tmp_path / "elevation.npy", elevation)
    return [
        "export",
        str(_set(tmp_path, georef)),
        str(tmp_path / "out"),
        "--dataset",
        str(dataset_root),
        "--elevation",
        str(tmp_path / "elevation.npy"),
    ]


def _camera_translation(image: CameraImage, shift: np.ndarray) -> np.ndarray:
    return np.asarray((shifted(image.global_from_ego, shift) @ image.calibration.ego_from_cam).translation)


def test_refined_poses_sources_and_values(dataset_root: Path) -> None:
    """SfM-posed images get their SfM pose; every other image its WIGO pose corrected by the correction
    interpolated between the SfM keyframes around it (a hand computation)."""
    dataset = load_dataset(dataset_root)
    workspace = Workspace.for_dataset(dataset_root)
    write_reconstruction(dataset, workspace)
    poses = refined_poses(dataset, workspace, SITE_ID)
    posed = {im.token for im in sfm_images(dataset)}
    for image in dataset.scenes[0].all_images():
        refined = poses[image.token]
        assert refined.source == ("sfm" if image.token in posed else "wigo+sfm")
        expected = shifted(image.global_from_ego, expected_shift(dataset, image))
        np.testing.assert_allclose(refined.global_from_ego.translation, expected.translation, atol=1e-9)
        np.testing.assert_allclose(refined.global_from_ego.rotation, expected.rotation, atol=1e-9)
    sweep = dataset.scenes[0].images["CAM_FRONT"][1]
    assert not sweep.is_key_frame and expected_shift(dataset, sweep)[2] == pytest.approx(1.0)


def test_cama_export_refined_by_default(
    tmp_path: Path, georef: Georeference, dataset_root: Path, plane_elevation: np.ndarray
) -> None:
    """Odometry rows of SfM-posed images equal the SfM poses (times the extrinsics); sources in the sidecar;
    the export imports back."""
    dataset = load_dataset(dataset_root)
    write_reconstruction(dataset, Workspace.for_dataset(dataset_root))
    result = runner.invoke(app, _export_args(tmp_path, georef, dataset_root, plane_elevation))
    assert result.exit_code == 0, result.output
    folder = tmp_path / "out" / "all_clips" / dataset.scenes[0].name
    rows = _rows(folder, "CAM_FRONT")
    images = dataset.scenes[0].images["CAM_FRONT"]
    for row, image in zip(rows, images, strict=True):
        np.testing.assert_allclose(
            row[1:4], _camera_translation(image, expected_shift(dataset, image)), atol=1e-6
        )
    for i, image in enumerate(sfm_images(dataset)):
        row = rows[images.index(image)]
        np.testing.assert_allclose(row[1:4], _camera_translation(image, sfm_shift(i)), atol=1e-6)
    sources = json.loads((folder / "odometry/pose_sources.json").read_text())["scmv_camera_front.txt"]
    assert sources["rows"] == ["sfm" if im.is_key_frame else "wigo+sfm" for im in images]
    assert sources["counts"] == {"sfm": 3, "wigo+sfm": 3}
    back = tmp_path / "back.json"
    assert runner.invoke(app, ["import", str(folder), "--out", str(back)]).exit_code == 0
    assert [e.id for e in AnnotationSet.read_json(back).elements] == ["el-1"]


def test_coarse_only_when_asked(
    tmp_path: Path, georef: Georeference, dataset_root: Path, plane_elevation: np.ndarray
) -> None:
    """`--poses coarse` writes the logged poses (no reconstruction needed), sources `coarse`."""
    dataset = load_dataset(dataset_root)
    args = _export_args(tmp_path, georef, dataset_root, plane_elevation)
    result = runner.invoke(app, [*args, "--poses", "coarse"])
    assert result.exit_code == 0, result.output
    folder = tmp_path / "out" / "all_clips" / dataset.scenes[0].name
    images = dataset.scenes[0].images["CAM_FRONT"]
    for row, image in zip(_rows(folder, "CAM_FRONT"), images, strict=True):
        np.testing.assert_allclose(row[1:4], _camera_translation(image, np.zeros(3)), atol=1e-6)
    sources = json.loads((folder / "odometry/pose_sources.json").read_text())
    assert sources["scmv_camera_front.txt"]["counts"] == {"coarse": len(images)}


def test_refined_without_sfm_is_exit_2(tmp_path: Path, georef: Georeference, dataset_root: Path) -> None:
    """Refined poses without poses.json: exit 2, naming the file and the two ways out; nothing written."""
    write_reconstruction(load_dataset(dataset_root), Workspace.for_dataset(dataset_root), with_sfm=False)
    args = ["export", str(_set(tmp_path, georef)), str(tmp_path / "out"), "--dataset", str(dataset_root)]
    for extra in ([], ["--format", "maptr"]):
        result = runner.invoke(app, [*args, *extra])
        assert result.exit_code == 2
        output = " ".join(result.output.split())  # the console may wrap the message
        assert "poses.json" in output and "cama sfm" in output and "--poses coarse" in output
    assert not (tmp_path / "out").exists()


def test_maptr_refined_pose_source(tmp_path: Path, georef: Georeference, dataset_root: Path) -> None:
    """MapTR samples take the CAM_FRONT key frame's refined pose and say its source; import still works."""
    dataset: Dataset = load_dataset(dataset_root)
    write_reconstruction(dataset, Workspace.for_dataset(dataset_root))
    out = tmp_path / "maptr.json"
    args = [
        "export",
        str(_set(tmp_path, georef)),
        str(out),
        "--format",
        "maptr",
        "--dataset",
        str(dataset_root),
    ]
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    samples = read_maptr(out).samples
    assert [s.pose_source for s in samples] == ["sfm"] * 3
    for i, (sample, image) in enumerate(zip(samples, sfm_images(dataset), strict=True)):
        expected = shifted(image.global_from_ego, sfm_shift(i))
        np.testing.assert_allclose(sample.ego_pose.translation, expected.translation, atol=1e-9)
    assert (
        runner.invoke(
            app, ["import", str(out), "--format", "maptr", "--out", str(tmp_path / "b.json")]
        ).exit_code
        == 0
    )
