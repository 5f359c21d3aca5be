"""nuScenes-CAMAv2 export (issue 24.5): a nuScenes root whose ego_pose.json holds the refined poses (our loader
reads them back), every other table unchanged, lidar records corrected by the nearest camera image, map vectors
in each sample's refined ego frame, pose sources counted; and the MapTR export's vectors follow the lookup."""

import json
import math
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from shapely.geometry import LineString, Point

from annotations import AnnotationSet, Georeference, MapElement
from annotations.maptr_format import export_maptr, read_maptr
from annotations.nuscenes_cama_format import export_nuscenes_cama
from annotations.poses import PoseLookup, PoseSource, SourcedPose, coarse_pose
from annotations.transforms import global_from_ego_points, rotation_from_quaternion, site_from_global_points
from cama_pipeline.data import CameraImage, Dataset, Pose, load_dataset
from tests.annotations.annotation_helpers import element_kwargs
from tests.conftest import GeneratedSite
from tests.data.nuscenes_fixture import LIDAR_CHANNEL, sample_data_token, write_nuscenes_fixture

CAM_FRONT_DELTA = Pose(np.array([0.3, -0.2, 0.5]), np.array([math.cos(0.005), 0.0, 0.0, math.sin(0.005)]))
"""ego_from_refined-ego of the CAM_FRONT images (an SfM-like correction: 0.6 m and 0.57 deg)."""
OTHER_SHIFT = np.array([1.0, 2.0, 0.25])
"""Global shift of every other camera's image but CAM_BACK's (left coarse)."""


def shifting_lookup(image: CameraImage) -> SourcedPose:
    """CAM_FRONT: perturbed in its ego frame (`sfm`); CAM_BACK: logged (`coarse`); others: shifted (`wigo+sfm`)."""
    logged = image.global_from_ego
    if image.channel == "CAM_FRONT":
        return SourcedPose(logged @ CAM_FRONT_DELTA, "sfm")
    if image.channel == "CAM_BACK":
        return SourcedPose(logged, "coarse")
    return SourcedPose(Pose(OTHER_SHIFT, np.array([1.0, 0.0, 0.0, 0.0])) @ logged, "wigo+sfm")


def _flat_lines(dataset: Dataset, georef: Georeference) -> AnnotationSet:
    """One level divider 5 to 20 m ahead of each key frame's logged CAM_FRONT pose, slightly to the left."""
    elements = []
    for frame in (f for scene in dataset.scenes for f in scene.frames):
        pose = frame.images["CAM_FRONT"].global_from_ego
        ego = np.array([[5.0, 1.0, 0.0], [12.0, 2.0, 0.0], [20.0, 1.5, 0.0]])
        world = pose.transform_points(ego)
        world[:, 2] = pose.translation[2]
        site = site_from_global_points(world, georef.site_origin_xy)
        kwargs = element_kwargs(
            id=f"line-{frame.token}", points_2d=site[:, :2].tolist(), points_3d=site.tolist()
        )
        elements.append(MapElement.model_validate(kwargs))
    return AnnotationSet(site_id="site-a", georeference=georef, elements=elements)


def _on_some_line(points: np.ndarray, annotations: AnnotationSet) -> bool:
    """Whether every global point lies on one element's polyline (xy within 1e-6 m, z equal)."""
    georef = annotations.georeference
    for element in annotations.elements:
        site = np.asarray(element.points_3d)
        line = LineString((site[:, :2] + np.asarray(georef.site_origin_xy)).tolist())
        if all(line.distance(Point(p[:2])) < 1e-6 and abs(p[2] - site[0, 2]) < 1e-6 for p in points):
            return True
    return False


def _files(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir()) if p.is_file()}


@pytest.fixture()
def tiny_export(tiny_site: GeneratedSite, georef: Georeference, tmp_path: Path) -> tuple[Path, Dataset, Path]:
    """The tiny site exported with the shifting lookup: (source root, source data set, output root)."""
    root = tiny_site.result.out_dir / "nuscenes"
    dataset = load_dataset(root)
    annotations = _flat_lines(dataset, georef)
    out = tmp_path / "nuscenes-cama"
    result = export_nuscenes_cama(annotations, root, dataset, out, poses=shifting_lookup)
    assert result.version == f"{dataset.version}-cama" and result.version_dir == out / result.version
    return root, dataset, out


def test_tiny_site_poses_tables_and_links(tiny_export: tuple[Path, Dataset, Path]) -> None:
    """Our loader reads the new root (one version, `-cama`); every image's global_from_ego is the lookup's;
    every other table is byte-identical (hard-linked here); ego_pose keeps tokens, order, fields, timestamps;
    samples/, sweeps/, maps/ ... are absolute links to the source's."""
    root, dataset, out = tiny_export
    exported = load_dataset(out)
    assert exported.version == f"{dataset.version}-cama"
    images = list(exported.camera_images())
    assert len(images) == len(list(dataset.camera_images()))
    for image in images:
        want = shifting_lookup(dataset.image(image.token)).global_from_ego
        np.testing.assert_allclose(image.global_from_ego.translation, want.translation, atol=1e-9)
        np.testing.assert_allclose(image.global_from_ego.rotation, want.rotation, atol=1e-12)
        assert image.path.read_bytes() == dataset.image(image.token).path.read_bytes()
    source_files, new_files = _files(root / dataset.version), _files(out / exported.version)
    assert set(new_files) == set(source_files) | {"map_vectors.json", "pose_sources.json"}
    for name in set(source_files) - {"ego_pose.json"}:
        assert new_files[name] == source_files[name], name
        assert os.path.samefile(root / dataset.version / name, out / exported.version / name)
    before = json.loads(source_files["ego_pose.json"])
    after = json.loads(new_files["ego_pose.json"])
    assert [(r["token"], list(r), r["timestamp"]) for r in before] == [
        (r["token"], list(r), r["timestamp"]) for r in after
    ]
    assert sorted(os.listdir(out)) == sorted(
        [p.name for p in root.iterdir() if p.name != dataset.version] + [exported.version]
    )
    for name in ("samples", "sweeps", "maps"):
        assert (out / name).is_symlink() and os.path.isabs(os.readlink(out / name))
        assert os.path.samefile(out / name, root / name)


def test_tiny_site_sources_and_map_vectors(
    tiny_export: tuple[Path, Dataset, Path], georef: Georeference
) -> None:
    """pose_sources.json counts each source (CAM_FRONT sfm, CAM_BACK coarse and logged, the rest wigo+sfm);
    map_vectors.json has every sample, its ego pose the refined CAM_FRONT one (no lidar in the synthetic set),
    and its vectors lie on the annotated lines through the refined pose, not through the logged one."""
    root, dataset, out = tiny_export
    version_dir = out / f"{dataset.version}-cama"
    sources = json.loads((version_dir / "pose_sources.json").read_text())
    images = list(dataset.camera_images())
    per_channel = {ch: sum(1 for im in images if im.channel == ch) for ch in ("CAM_FRONT", "CAM_BACK")}
    assert sources["counts"] == {
        "sfm": per_channel["CAM_FRONT"],
        "wigo+sfm": len(images) - sum(per_channel.values()),
        "wigo": 0,
        "coarse": per_channel["CAM_BACK"],
    }
    back = next(im for im in images if im.channel == "CAM_BACK")
    sample_data = {
        r["token"]: r for r in json.loads((root / dataset.version / "sample_data.json").read_text())
    }
    entry = sources["ego_poses"][sample_data[back.token]["ego_pose_token"]]
    assert entry == {
        "source": "coarse",
        "sample_data": back.token,
        "channel": "CAM_BACK",
        "correction_from": None,
        "logged": True,
    }
    annotations = _flat_lines(dataset, georef)
    vectors = read_maptr(version_dir / "map_vectors.json")
    frames = [f for scene in dataset.scenes for f in scene.frames]
    assert [s.sample_token for s in vectors.samples] == [f.token for f in frames]
    for sample, frame in zip(vectors.samples, frames, strict=True):
        refined = shifting_lookup(frame.images["CAM_FRONT"]).global_from_ego
        np.testing.assert_allclose(sample.ego_pose.translation, refined.translation, atol=1e-9)
        assert sample.pose_source == "sfm" and sample.vectors
        rotation = rotation_from_quaternion(sample.ego_pose.rotation)
        logged = frame.images["CAM_FRONT"].global_from_ego
        for vector in sample.vectors:
            assert _on_some_line(
                global_from_ego_points(vector.points, rotation, sample.ego_pose.translation), annotations
            )
            wrong = global_from_ego_points(vector.points, logged.rotation_matrix(), logged.translation)
            assert not _on_some_line(wrong, annotations)


def test_a_data_set_loaded_by_scene(tiny_site: GeneratedSite, georef: Georeference, tmp_path: Path) -> None:
    """Loaded with two of its scenes (as `cama export` loads a site's scenes of a large data set), the export
    still rewrites the whole ego_pose.json: those scenes' images get the lookup's poses, every record of the
    other scenes stays as logged, and map_vectors.json lists only the samples of the exported scenes, though the
    annotations lie ahead of every frame (another scene's samples would otherwise get the site's vectors);
    `scenes` narrows them further, and a scene not loaded is refused before anything is written."""
    root = tiny_site.result.out_dir / "nuscenes"
    whole = load_dataset(root)
    chosen = [scene.name for scene in whole.scenes[:2]]
    assert len(whole.scenes) > len(chosen)
    dataset = load_dataset(root, scenes=chosen)
    annotations = _flat_lines(whole, georef)
    result = export_nuscenes_cama(annotations, root, dataset, tmp_path / "out", poses=shifting_lookup)
    exported = load_dataset(tmp_path / "out")
    for scene in whole.scenes:
        for image in scene.all_images():
            want = shifting_lookup(image) if scene.name in chosen else coarse_pose(image)
            got = exported.image(image.token).global_from_ego
            np.testing.assert_allclose(got.matrix(), want.global_from_ego.matrix(), atol=1e-9)
    vectors = read_maptr(result.version_dir / "map_vectors.json")
    frames = [f.token for scene in dataset.scenes for f in scene.frames]
    assert [s.sample_token for s in vectors.samples] == frames and result.samples == len(frames)
    assert all(sample.vectors for sample in vectors.samples)
    one = export_nuscenes_cama(
        annotations, root, dataset, tmp_path / "one", poses=shifting_lookup, scenes=chosen[1:]
    )
    assert {s.scene for s in read_maptr(one.version_dir / "map_vectors.json").samples} == {chosen[1]}
    left_out = whole.scenes[-1].name
    with pytest.raises(ValueError, match=f"scenes \\['{left_out}'\\]: not among the loaded scenes"):
        export_nuscenes_cama(
            annotations, root, dataset, tmp_path / "bad", poses=shifting_lookup, scenes=[left_out]
        )
    assert not (tmp_path / "bad").exists()


def _fixture_dataset(tmp_path: Path, *, n_samples: int = 3, with_lidar: bool = True) -> tuple[Path, Dataset]:
    """The hand-written fixture (6 cameras, a key frame and a sweep per sample, one lidar key frame each)."""
    fixture = write_nuscenes_fixture(
        tmp_path / "nuscenes", n_samples=n_samples, with_can=False, with_lidar=with_lidar
    )
    return fixture.root, load_dataset(fixture.root)


def _lookup(rules: Callable[[CameraImage], tuple[Pose, PoseSource] | None]) -> PoseLookup:
    def lookup(image: CameraImage) -> SourcedPose:
        found = rules(image)
        return coarse_pose(image) if found is None else SourcedPose(*found)

    return lookup


def _lidar_poses(version_dir: Path) -> dict[int, dict[str, Any]]:
    """LIDAR_TOP ego_pose records by sample index."""
    records = {r["token"]: r for r in json.loads((version_dir / "ego_pose.json").read_text())}
    return {i: records[f"ep-{sample_data_token(LIDAR_CHANNEL, i)}"] for i in range(3)}


def test_lidar_takes_nearest_camera_correction(tmp_path: Path, georef: Georeference) -> None:
    """With CAM_FRONT left coarse, each lidar record (at the sample time) takes the correction of the nearest
    refined image, CAM_FRONT_RIGHT's key frame 5 ms later, applied to its own logged pose; the map vectors'
    reference is the lidar's corrected pose; pose_sources names the image."""
    root, dataset = _fixture_dataset(tmp_path)
    yaw = Pose(np.zeros(3), np.array([math.cos(0.01), 0.0, 0.0, math.sin(0.01)]))

    def rules(image: CameraImage) -> tuple[Pose, PoseSource] | None:
        if image.channel == "CAM_FRONT":
            return None
        offset = np.array([0.01 * (image.timestamp_us // 1000 % 97), 1.0, 0.5])
        return Pose(offset, yaw.rotation) @ image.global_from_ego, "sfm"

    poses = _lookup(rules)
    source_lidar = _lidar_poses(root / dataset.version)
    result = export_nuscenes_cama(
        AnnotationSet(site_id="s", georeference=georef), root, dataset, tmp_path / "out", poses=poses
    )
    assert result.camera_records == 36 and result.borrowed_records == 3
    assert result.counts == {"sfm": 30 + 3, "wigo+sfm": 0, "wigo": 0, "coarse": 6}
    lidar = _lidar_poses(result.version_dir)
    sources = json.loads((result.version_dir / "pose_sources.json").read_text())
    vectors = read_maptr(result.version_dir / "map_vectors.json")
    for i in range(3):
        camera = dataset.image(sample_data_token("CAM_FRONT_RIGHT", i))
        correction = poses(camera).global_from_ego @ camera.global_from_ego.inverse()
        logged = Pose(source_lidar[i]["translation"], source_lidar[i]["rotation"])
        want = correction @ logged
        np.testing.assert_allclose(lidar[i]["translation"], want.translation, atol=1e-9)
        np.testing.assert_allclose(lidar[i]["rotation"], want.rotation, atol=1e-12)
        entry = sources["ego_poses"][lidar[i]["token"]]
        assert entry["correction_from"] == camera.token and entry["source"] == "sfm" and not entry["logged"]
        np.testing.assert_allclose(vectors.samples[i].ego_pose.translation, want.translation, atol=1e-9)


def test_lidar_beyond_the_gap_keeps_its_logged_pose(tmp_path: Path, georef: Georeference) -> None:
    """Only sample 0's images refined: sample 1's lidar (its nearest refined image, a sweep, 0.25 s away) is
    corrected; sample 2's (0.75 s away, over the 0.5 s gap) keeps its logged record, source coarse."""
    root, dataset = _fixture_dataset(tmp_path)
    shift = Pose(np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0, 0.0]))
    first = {f"sd-{ch}-0-{k}" for ch in ("CAM_FRONT", "CAM_BACK") for k in (0, 1)}
    poses = _lookup(lambda im: (shift @ im.global_from_ego, "wigo") if im.token in first else None)
    source_lidar = _lidar_poses(root / dataset.version)
    annotations = AnnotationSet(site_id="s", georeference=georef)
    result = export_nuscenes_cama(annotations, root, dataset, tmp_path / "out", poses=poses)
    lidar = _lidar_poses(result.version_dir)
    sources = json.loads((result.version_dir / "pose_sources.json").read_text())["ego_poses"]
    for i, moved in ((0, True), (1, True), (2, False)):
        dz = lidar[i]["translation"][2] - source_lidar[i]["translation"][2]
        assert dz == pytest.approx(1.0 if moved else 0.0, abs=1e-9)
        assert sources[lidar[i]["token"]]["source"] == ("wigo" if moved else "coarse")
    assert sources[lidar[2]["token"]]["logged"] and lidar[2] == source_lidar[2]
    assert result.borrowed_records == 2 and result.counts["wigo"] == 4 + 2


def test_coarse_lookup_keeps_ego_pose_bytes(tmp_path: Path, georef: Georeference) -> None:
    """A lookup with no refined pose (and so no correction for the lidar within the gap): ego_pose.json comes
    out byte for byte as the source's (indented here), every record `coarse` and logged; copies when asked."""
    root, dataset = _fixture_dataset(tmp_path)
    annotations = AnnotationSet(site_id="s", georeference=georef)
    out = tmp_path / "out"
    result = export_nuscenes_cama(annotations, root, dataset, out, poses=coarse_pose, link_tables=False)
    source = root / dataset.version
    assert (result.version_dir / "ego_pose.json").read_bytes() == (source / "ego_pose.json").read_bytes()
    n = len(json.loads((source / "ego_pose.json").read_text()))
    assert result.counts == {"sfm": 0, "wigo+sfm": 0, "wigo": 0, "coarse": n} and result.kept_records == n
    assert result.tables_linked == 0 and result.tables_copied == len(_files(source)) - 1
    assert not os.path.samefile(source / "sample.json", result.version_dir / "sample.json")


def test_maptr_vectors_follow_the_lookup(tmp_path: Path, georef: Georeference) -> None:
    """The MapTR export's vectors are in the lookup's ego frame: a lookup moving every pose by d (global) moves
    every ego-frame vector point by -R^T d."""
    _, dataset = _fixture_dataset(tmp_path, with_lidar=False)
    shift = np.array([0.7, -0.4, 0.3])
    pose = dataset.scenes[0].frames[0].images["CAM_FRONT"].global_from_ego
    world = pose.transform_points(np.array([[4.0, 1.0, 0.0], [10.0, 1.5, 0.0]]))
    site = site_from_global_points(world, georef.site_origin_xy)
    element = MapElement.model_validate(
        element_kwargs(points_2d=site[:, :2].tolist(), points_3d=site.tolist())
    )
    annotations = AnnotationSet(site_id="s", georeference=georef, elements=[element])
    shifted = _lookup(lambda im: (Pose(shift, np.array([1.0, 0, 0, 0])) @ im.global_from_ego, "wigo"))
    logged = read_maptr(export_maptr(annotations, dataset, tmp_path / "a.json", poses=coarse_pose))
    moved = read_maptr(export_maptr(annotations, dataset, tmp_path / "b.json", poses=shifted))
    for before, after in zip(logged.samples, moved.samples, strict=True):
        rotation = rotation_from_quaternion(before.ego_pose.rotation)
        assert after.pose_source == "wigo" and len(before.vectors) == len(after.vectors) == 1
        expected = np.asarray(before.vectors[0].points) - rotation.T @ shift
        np.testing.assert_allclose(after.vectors[0].points, expected, atol=1e-9)


def test_bad_inputs_name_the_file_and_write_nothing(tmp_path: Path, georef: Georeference) -> None:
    """A non-empty output, a missing version folder, a broken ego_pose.json, a data set of another root:
    ValueError naming the file, nothing written."""
    root, dataset = _fixture_dataset(tmp_path)
    annotations = AnnotationSet(site_id="s", georeference=georef)
    busy = tmp_path / "busy"
    busy.mkdir()
    (busy / "x").write_text("x")
    with pytest.raises(ValueError, match="busy: the output must be a new or empty folder"):
        export_nuscenes_cama(annotations, root, dataset, busy, poses=coarse_pose)
    other_root, _ = _fixture_dataset(tmp_path / "other", n_samples=2)
    out = tmp_path / "out"
    with pytest.raises(ValueError, match=r"sample_data\.json.*not loaded from this root"):
        export_nuscenes_cama(annotations, other_root, dataset, out, poses=coarse_pose)
    (root / dataset.version / "ego_pose.json").write_text("[{")
    with pytest.raises(ValueError, match=r"ego_pose\.json: invalid JSON"):
        export_nuscenes_cama(annotations, root, dataset, out, poses=coarse_pose)
    (root / dataset.version).rename(root / "elsewhere")
    with pytest.raises(ValueError, match=f"{dataset.version}: no version folder"):
        export_nuscenes_cama(annotations, root, dataset, out, poses=coarse_pose)
    assert not out.exists()


def test_progress_covers_every_long_step(
    tmp_path: Path, georef: Georeference, caplog: pytest.LogCaptureFixture
) -> None:
    """On nuScenes trainval the tables, the 2.6 million ego poses and the two rewritten files take most of the
    export's time: each has a bar (lines when output is not a terminal), ending at its total."""
    root, dataset = _fixture_dataset(tmp_path)
    caplog.set_level("INFO", logger="annotations.nuscenes_cama_format")
    result = export_nuscenes_cama(
        AnnotationSet(site_id="s", georeference=georef),
        root,
        dataset,
        tmp_path / "out",
        poses=shifting_lookup,
        show_progress=True,
    )
    records = len(json.loads((root / dataset.version / "ego_pose.json").read_text()))
    sample_data = len(json.loads((root / dataset.version / "sample_data.json").read_text()))
    lines = [r.getMessage() for r in caplog.records if r.getMessage().startswith("cama export: ")]
    finished = {line.split(": ", 1)[1].split(" (")[0] for line in lines if "done in" in line}
    assert finished == {
        "tables 6/6",
        f"ego poses {sample_data}/{sample_data}",
        f"map vectors {result.samples}/{result.samples}",
        f"ego_pose.json {records}/{records}",
        f"pose_sources.json {records}/{records}",
    }
