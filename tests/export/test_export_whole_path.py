"""`cama export` of a real reconstruction (the tiny site after `cama run`): CAMA's release layout in site mode
with clip data, every file name and array shape, odometry rows equal to the SfM poses of the same images, and the
labels importing back; plus the MapTR samples in the refined ego frame."""

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from typer.testing import CliRunner

from annotations import AnnotationSet
from annotations.cama_odometry import CAMERA_NAME_FROM_CHANNEL, timestamp_ms
from annotations.lift import lift_element
from cama_pipeline.bev import read_bev
from cama_pipeline.data import load_dataset
from cama_pipeline.sfm.io import read_refined_poses
from cama_pipeline.site.io import read_site_scenes
from cama_pipeline.workspace import Workspace
from cama_studio.cli import app
from cama_studio.pipeline import PipelineResult
from tests.conftest import GeneratedSite

runner = CliRunner()
CAMERAS = sorted(CAMERA_NAME_FROM_CHANNEL.values())


@pytest.fixture(scope="module")
def site_export(
    whole_path: PipelineResult, tiny_site: GeneratedSite, tmp_path_factory: pytest.TempPathFactory
):
    """The lifted proposals exported in site mode with clip data, and what the test needs to check them."""
    dataset_root = tiny_site.result.out_dir / "nuscenes"
    workspace = Workspace(whole_path.workspace)
    site_id, proposals_path = next(iter(whole_path.proposals.items()))
    proposals = AnnotationSet.read_json(proposals_path)
    elevation = read_bev(workspace.surface_bev(site_id), ["elevation"]).require("elevation")
    lifted = [lift_element(e, elevation, proposals.georeference, strict=False) for e in proposals.elements]
    tmp = tmp_path_factory.mktemp("site-export")
    source = tmp / "lifted.json"
    proposals.model_copy(update={"elements": lifted}).write_json(source)
    np.save(tmp / "elevation.npy", elevation)
    out = tmp / "release"
    args = [
        "export",
        str(source),
        str(out),
        "--dataset",
        str(dataset_root),
        "--workspace",
        str(workspace.root),
    ]
    result = runner.invoke(
        app, [*args, "--elevation", str(tmp / "elevation.npy"), "--mode", "site", "--with-clip-data"]
    )
    assert result.exit_code == 0, result.output
    return out, site_id, workspace, load_dataset(dataset_root), len(lifted)


def test_release_layout_names_and_shapes(site_export) -> None:
    out, site_id, _workspace, dataset, _count = site_export
    site2clip = json.loads((out / "site2clip.json").read_text())
    scenes = sorted(p.name for p in (out / "all_clips").iterdir())
    assert site2clip == {site_id: scenes} and set(scenes) <= {s.name for s in dataset.scenes}
    site_map = np.load(out / "site2clip" / f"{site_id}_vision_road_mlp_ft.npy")
    assert site_map.shape == (6000, 6000) and site_map.dtype == np.float32 and np.isfinite(site_map).all()
    assert isinstance(json.loads((out / "site2clip" / f"{site_id}_map_labels.json").read_text()), list)
    for scene in scenes:
        folder = out / "all_clips" / scene
        assert np.load(folder / "maps/vision_road_mlp_ft.npy", mmap_mode="r").shape == (6000, 6000)
        labels = json.loads((folder / "maps/map_labels.json").read_text())
        assert {item["attrs"]["type"] for item in labels} <= {"lane_marking", "Road_teeth", "Crosswalk_Line"}
        odometry = sorted(p.name for p in (folder / "odometry").glob("*.txt"))
        assert odometry == [f"mcmv_{camera}.txt" for camera in CAMERAS]
        attribute = json.loads((folder / "attribute.json").read_text())
        assert sorted(attribute["sync"]) == CAMERAS
        for camera in CAMERAS:
            stamps = attribute["sync"][camera]
            assert len(stamps) == len(attribute["sync"]["camera_front"])
            assert (folder / camera / f"{stamps[0]}.jpg").is_file()
            mask = cv2.imread(str(folder / f"lane_ins_{camera}" / f"{stamps[0]}.png"), cv2.IMREAD_UNCHANGED)
            assert mask is not None and mask.dtype == np.uint16
            assert {int(v) // 1000 for v in np.unique(mask) if v} <= {1, 7}


def test_odometry_rows_are_the_sfm_poses(site_export) -> None:
    out, site_id, workspace, dataset, _count = site_export
    sfm = read_refined_poses(workspace.sfm_poses(site_id))
    checked = 0
    for folder in sorted((out / "all_clips").iterdir()):
        sidecar = json.loads((folder / "maps/georeference.json").read_text())
        origin = np.asarray(sidecar["world_origin_global"])
        scene = next(s for s in dataset.scenes if s.name == folder.name)
        by_key = {(im.channel, timestamp_ms(im.timestamp_us)): im for im in scene.all_images()}
        for channel, camera in CAMERA_NAME_FROM_CHANNEL.items():
            lines = (folder / "odometry" / f"mcmv_{camera}.txt").read_text().splitlines()
            assert lines and not lines[0].startswith("#")
            for line in lines:
                t_text = line.split()[0]
                assert len(t_text.split(".")[1]) == 3
                row = np.array(line.split(), dtype=float)
                image = by_key[(channel, round(row[0] * 1000))]
                if image.token not in sfm:
                    continue
                global_from_cam = sfm[image.token] @ image.calibration.ego_from_cam.matrix()
                np.testing.assert_allclose(row[1:4] + origin, global_from_cam[:3, 3], atol=1e-5)
                checked += 1
    assert checked > 0


def test_labels_import_back_in_site_coordinates(site_export, tmp_path: Path) -> None:
    out, site_id, _workspace, _dataset, count = site_export
    back = tmp_path / "back.json"
    result = runner.invoke(
        app, ["import", str(out / "site2clip" / f"{site_id}_map_labels.json"), "--out", str(back)]
    )
    assert result.exit_code == 0, result.output
    assert 0 < len(AnnotationSet.read_json(back).elements) <= count


def test_nuscenes_cama_root_carries_the_sfm_poses(
    site_export, tiny_site: GeneratedSite, tmp_path: Path
) -> None:
    """`--format nuscenes-cama`: a nuScenes root our loader reads, whose camera ego poses are the SfM poses for
    the images SfM posed; the map vectors beside it for the site's samples only; the scene the site left out
    (the night clip) keeps its logged poses and gets no map vectors (nobody annotated it)."""
    _out, site_id, workspace, dataset, _count = site_export
    source = tmp_path / "set.json"
    AnnotationSet.read_json(next(iter(workspace.root.glob("proposals/*.json")))).write_json(source)
    out = tmp_path / "nuscenes-cama"
    dataset_root = tiny_site.result.out_dir / "nuscenes"
    args = ["export", str(source), str(out), "--format", "nuscenes-cama", "--dataset", str(dataset_root)]
    result = runner.invoke(app, [*args, "--workspace", str(workspace.root)])
    assert result.exit_code == 0, result.output
    refined = load_dataset(out)
    version = next(p for p in out.iterdir() if p.name.endswith("-cama"))
    assert (version / "map_vectors.json").is_file() and (version / "pose_sources.json").is_file()
    sfm = read_refined_poses(workspace.sfm_poses(site_id))
    posed = [im for scene in refined.scenes for im in scene.all_images() if im.token in sfm]
    assert posed
    for image in posed:
        np.testing.assert_allclose(image.global_from_ego.matrix(), sfm[image.token], atol=1e-6)
    site_scenes = set(read_site_scenes(workspace.sites_index()))
    left_out = [scene for scene in dataset.scenes if scene.name not in site_scenes]
    assert left_out, "the tiny site's night clip should be left out of its site"
    samples = json.loads((version / "map_vectors.json").read_text())["samples"]
    assert samples and {s["scene"] for s in samples} == site_scenes
    sources = json.loads((version / "pose_sources.json").read_text())["ego_poses"]
    for scene in left_out:
        for image in scene.all_images():
            kept = refined.image(image.token).global_from_ego
            np.testing.assert_array_equal(kept.matrix(), image.global_from_ego.matrix())
    logged = {entry["sample_data"] for entry in sources.values() if entry["logged"]}
    assert {image.token for scene in left_out for image in scene.all_images()} <= logged


def test_maptr_keeps_to_the_site_scenes(site_export, tiny_site: GeneratedSite, tmp_path: Path) -> None:
    """Refined MapTR samples: only the site's scenes (a scene the site left out would carry logged poses), and
    every sample's pose from the reconstruction."""
    _out, site_id, workspace, _dataset, _count = site_export
    source = tmp_path / "set.json"
    AnnotationSet.read_json(next(iter(workspace.root.glob("proposals/*.json")))).write_json(source)
    out = tmp_path / "maptr.json"
    dataset_root = tiny_site.result.out_dir / "nuscenes"
    args = ["export", str(source), str(out), "--format", "maptr", "--dataset", str(dataset_root)]
    assert runner.invoke(app, [*args, "--workspace", str(workspace.root)]).exit_code == 0
    samples = json.loads(out.read_text())["samples"]
    site_scenes = {
        entry["scene"] for entry in json.loads(workspace.site_manifest(site_id).read_text())["scenes"]
    }
    assert samples and {s["scene"] for s in samples} <= site_scenes
    assert {s["pose_source"] for s in samples} <= {"sfm", "wigo+sfm", "wigo"}


@pytest.mark.parametrize("export_format", ["maptr", "cama", "nuscenes-cama"])
def test_a_large_data_set_is_read_by_the_sites_scenes(
    site_export,
    tiny_site: GeneratedSite,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    export_format,
) -> None:
    """Every format reads only the workspace's sites' scenes of the data set (trainval's 850 would take minutes
    and gigabytes); nuscenes-cama too, keeping the other scenes' ego poses as logged."""
    from cama_pipeline.export import run as export_run

    _out, site_id, workspace, _dataset, _count = site_export
    asked: list[object] = []

    def recording_load(root, **kwargs):
        asked.append(kwargs.get("scenes"))
        return load_dataset(root, **kwargs)

    monkeypatch.setattr(export_run, "load_dataset", recording_load)
    source = tmp_path / "set.json"
    AnnotationSet.read_json(next(iter(workspace.root.glob("proposals/*.json")))).write_json(source)
    dataset_root = tiny_site.result.out_dir / "nuscenes"
    args = [
        "export",
        str(source),
        str(tmp_path / "out"),
        "--format",
        export_format,
        "--dataset",
        str(dataset_root),
    ]
    if export_format == "cama":  # its map needs heights
        np.save(
            tmp_path / "elevation.npy",
            read_bev(workspace.surface_bev(site_id), ["elevation"]).require("elevation"),
        )
        args += ["--elevation", str(tmp_path / "elevation.npy")]
    result = runner.invoke(app, [*args, "--workspace", str(workspace.root)])
    assert result.exit_code == 0, result.output
    assert asked == [read_site_scenes(workspace.sites_index())]
