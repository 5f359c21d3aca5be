"""CAMA's public release layout (issue 24 points 2, 3, 7): file names and shapes, the [u, v] convention on a
hand-placed element, odometry equal to the lookup's poses of that scene only, the observed-range cut, site mode's
site2clip files, a round trip within one cell, and clear errors."""

import inspect
import json
import re
from pathlib import Path

import cv2
import numpy as np
import pytest
from shapely.geometry import LineString, Polygon

from annotations.cama_cut import DEFAULT_OBSERVED_RADIUS_M
from annotations.cama_import import import_cama
from annotations.cama_odometry import CAMERA_NAME_FROM_CHANNEL
from annotations.cama_release import CamaReleaseResult, export_cama_release
from annotations.poses import SourcedPose
from cama_pipeline.data import CameraImage
from cama_pipeline.surface.config import SurfaceConfig
from tests.annotations.release_helpers import (
    RADIUS_M,
    SCENES,
    SITE,
    SITE_ORIGIN,
    annotation_set,
    export_release,
    lookup_camera_pose,
    plane_raster,
    plane_z,
    release_dataset,
)

CAMS = sorted(CAMERA_NAME_FROM_CHANNEL.values())


@pytest.fixture(scope="module")
def clip(tmp_path_factory: pytest.TempPathFactory) -> CamaReleaseResult:
    """One clip-mode export of scene-a and scene-b (scene-c, the night scene, left out)."""
    return export_release(tmp_path_factory.mktemp("clip") / "out")


@pytest.fixture(scope="module")
def site(tmp_path_factory: pytest.TempPathFactory) -> CamaReleaseResult:
    """One site-mode export of the same."""
    return export_release(tmp_path_factory.mktemp("site") / "out", "site")


def _files(root: Path) -> set[str]:
    return {str(p.relative_to(root)) for p in root.rglob("*") if p.is_file()}


def _labels(path: Path) -> dict[str, dict]:  # type: ignore[type-arg]
    return {str(item["id"]): item for item in json.loads(path.read_text())}


def _sidecar(path: Path) -> dict:  # type: ignore[type-arg]
    return json.loads(path.read_text())


def test_clip_layout_files_and_shapes(clip: CamaReleaseResult) -> None:
    """Exactly the release's files (plus our sidecars) per scene folder, named after the scene, not the set's
    site id 'bev'; a 3000 x 3000 float32 elevation without NaN; no site2clip in clip mode."""
    out = clip.out
    expected = set()
    for scene in SCENES:
        expected |= {
            f"all_clips/{scene}/maps/{name}"
            for name in (
                "map_labels.json",
                "vision_road_mlp_ft.npy",
                "georeference.json",
                "elevation_filled.png",
            )
        }
        expected |= {f"all_clips/{scene}/odometry/scmv_{cam}.txt" for cam in CAMS}
        expected.add(f"all_clips/{scene}/odometry/pose_sources.json")
    assert _files(out) == expected
    assert [s.scene for s in clip.scenes] == list(SCENES) and clip.site_files == ()
    for scene in SCENES:
        elevation = np.load(out / f"all_clips/{scene}/maps/vision_road_mlp_ft.npy")
        assert elevation.shape == (3000, 3000) and elevation.dtype == np.float32
        assert np.isfinite(elevation).all()
        filled = cv2.imread(str(out / f"all_clips/{scene}/maps/elevation_filled.png"), cv2.IMREAD_UNCHANGED)
        assert filled is not None and filled.shape == (3000, 3000) and set(np.unique(filled)) <= {0, 255}
        assert 0 < int((filled == 255).sum()) == clip.scenes[SCENES.index(scene)].filled_cells < filled.size


def test_uv_convention_on_a_hand_placed_element(clip: CamaReleaseResult) -> None:
    """scene-a's cameras average global (1021, 2000): the world origin. Site (10, 2) = world (-11, 2): u = (2 +
    150) / 0.1 = 1520 (column, from y), v = (-11 + 150) / 0.1 = 1390 (row, from x); the raster's [v, u] holds z."""
    folder = clip.out / "all_clips/scene-a"
    assert _sidecar(folder / "maps/georeference.json")["world_origin_global"] == [1021.0, 2000.0, 0.0]
    near = _labels(folder / "maps/map_labels.json")["near-a"]
    assert near["attrs"] == {"type": "lane_marking"}
    assert near["shape_type"] == "polyline" and near["struct_type"] == "parsing"
    data = np.asarray(near["data"])
    assert near["point_attrs"] == [[] for _ in data]
    np.testing.assert_allclose(data[[0, -1]], [[1520.0, 1390.0], [1520.0, 1490.0]], atol=1e-6)
    np.testing.assert_allclose(
        data[:, 0], 1520.0, atol=1e-6
    )  # densified along the segment, 10 m in 0.5 m steps
    assert len(data) == 21 and np.abs(np.diff(data[:, 1])).max() <= 5.0 + 1e-6
    elevation = np.load(folder / "maps/vision_road_mlp_ft.npy")
    assert elevation[1390, 1520] == pytest.approx(float(plane_z(10.0, 2.0)), abs=1e-4)
    assert elevation[1490, 1520] == pytest.approx(float(plane_z(20.0, 2.0)), abs=1e-4)


def test_odometry_rows_are_the_lookup_poses_of_that_scene(clip: CamaReleaseResult) -> None:
    """One row per image of the scene only (scene-b's and the night scene's never), no header, t with exactly three
    decimals, camera to world: the lookup's pose (not the logged one) less the world origin."""
    dataset = release_dataset()
    for scene in SCENES:
        folder = clip.out / "all_clips" / scene
        origin = np.array(_sidecar(folder / "maps/georeference.json")["world_origin_global"])
        sources = json.loads((folder / "odometry/pose_sources.json").read_text())
        for channel, cam in CAMERA_NAME_FROM_CHANNEL.items():
            lines = (folder / f"odometry/scmv_{cam}.txt").read_text().splitlines()
            images = dataset.scene_by_name(scene).images[channel]
            assert len(lines) == len(images)
            for line, image in zip(lines, images, strict=True):
                fields = line.split(" ")
                assert len(fields) == 8 and re.fullmatch(r"\d+\.\d{3}", fields[0]), line
                ms = (image.timestamp_us + 500) // 1000  # whole milliseconds, half up (16.666 ms -> 17)
                assert fields[0] == f"{ms // 1000}.{ms % 1000:03d}"
                pose = lookup_camera_pose(image)
                np.testing.assert_allclose(
                    np.array(fields[1:4], dtype=float), pose.translation - origin, atol=2e-6
                )
                np.testing.assert_allclose(
                    np.array(fields, dtype=object)[[7, 4, 5, 6]].astype(float), pose.rotation, atol=1e-8
                )
            rows = ["sfm" if im.is_key_frame else "wigo+sfm" for im in images]
            assert sources[f"scmv_{cam}.txt"] == {
                "counts": {"sfm": rows.count("sfm"), "wigo+sfm": rows.count("wigo+sfm")},
                "rows": rows,
            }
            assert sources[f"scmv_{cam}.txt"]["counts"] == {"sfm": 5, "wigo+sfm": 4}


def test_odometry_needs_a_pose_lookup(tmp_path: Path) -> None:
    """The pose lookup is a required argument (nothing falls back to the logged poses), and a lookup that has no
    pose for an image stops the export before anything is written."""
    assert inspect.signature(export_cama_release).parameters["poses"].default is inspect.Parameter.empty

    def no_pose(image: CameraImage) -> SourcedPose:
        raise KeyError(f"{image.token}: no refined pose")

    with pytest.raises(KeyError, match="scene-a-CAM_FRONT-0-0: no refined pose"):
        export_release(tmp_path / "out", poses=no_pose)
    assert not (tmp_path / "out").exists()


def test_observed_range_cut(clip: CamaReleaseResult) -> None:
    """scene-a gets what its cameras saw within 10 m, clipped there; scene-b only its own boundary."""
    labels_a = _labels(clip.out / "all_clips/scene-a/maps/map_labels.json")
    labels_b = _labels(clip.out / "all_clips/scene-b/maps/map_labels.json")
    assert set(labels_a) == {
        "near-a",
        "cross",
        "zigzag#1",
        "zigzag#2",
        "cw",
    }  # 'tip' enters by 0.3 m: dropped
    assert set(labels_b) == {"near-b"}
    assert labels_a["zigzag#2"]["element_id"] == "zigzag" and labels_a["near-a"]["element_id"] == "near-a"
    back = import_cama(clip.out / "all_clips/scene-a")
    np.testing.assert_allclose(back.by_id("cross").xy(), [[20.0, -10.5], [20.0, 10.5]], atol=1e-3)
    np.testing.assert_allclose(
        back.by_id("zigzag#1").xy(), [[5.0, 5.0], [15.0, 5.0], [15.0, 10.5]], atol=1e-3
    )
    np.testing.assert_allclose(
        back.by_id("zigzag#2").xy(), [[25.0, 10.5], [25.0, 5.0], [35.0, 5.0]], atol=1e-3
    )
    crosswalk = back.by_id("cw")
    assert crosswalk.closed
    assert Polygon(crosswalk.xy()).area == pytest.approx(4.0 * 5.5, abs=0.05)
    assert Polygon(crosswalk.xy()).bounds == pytest.approx((30.0, 5.0, 34.0, 10.5), abs=1e-3)


def test_clip_round_trip_within_one_cell(clip: CamaReleaseResult) -> None:
    """Import of a scene folder restores site coordinates, the set's georeference and the site name; an element
    inside the range comes back within one cell (0.1 m) in x, y and with z from the exported raster."""
    original = annotation_set()
    back = import_cama(clip.out / "all_clips/scene-a")
    assert back.site_id == SITE and back.georeference == original.georeference
    for element_id in ("near-a",):
        a, b = original.by_id(element_id), back.by_id(element_id)
        assert a.cls == b.cls
        np.testing.assert_allclose(b.xy(), a.xy(), atol=0.1)
        np.testing.assert_allclose(b.xy(), a.xy(), atol=1e-4)  # in fact far better than a cell
        xyz = b.xyz()
        assert xyz is not None
        np.testing.assert_allclose(xyz[:, 2], plane_z(xyz[:, 0], xyz[:, 1]), atol=1e-4)
    assert import_cama(clip.out / "all_clips/scene-b").by_id("near-b").cls == "boundary"


def test_site_layout_and_shared_frame(site: CamaReleaseResult) -> None:
    """Site mode: the site map and index in site2clip, mcmv odometry, every scene in the site's one frame (mean of
    all cameras: (1021, 2030)), its elevation the site's (6000 x 6000 float32, no NaN)."""
    out = site.out
    for name in ("map_labels.json", "vision_road_mlp_ft.npy", "georeference.json", "elevation_filled.png"):
        assert (out / f"site2clip/{SITE}_{name}").is_file()
    assert json.loads((out / "site2clip.json").read_text()) == {SITE: list(SCENES)}
    assert _files(out / "all_clips/scene-a/odometry") == {f"mcmv_{cam}.txt" for cam in CAMS} | {
        "pose_sources.json"
    }
    elevation = np.load(out / f"site2clip/{SITE}_vision_road_mlp_ft.npy", mmap_mode="r")
    assert elevation.shape == (6000, 6000) and elevation.dtype == np.float32
    assert not np.isnan(elevation).any()
    origins = {
        tuple(_sidecar(out / f"all_clips/{s}/maps/georeference.json")["world_origin_global"]) for s in SCENES
    }
    assert origins == {(1021.0, 2030.0, 0.0)}
    for scene in SCENES:
        scene_npy = out / f"all_clips/{scene}/maps/vision_road_mlp_ft.npy"
        assert scene_npy.stat().st_size == (out / f"site2clip/{SITE}_vision_road_mlp_ft.npy").stat().st_size
    near = _labels(out / "all_clips/scene-a/maps/map_labels.json")["near-a"]
    # site (10, 2) and (20, 2) = world (-11, -28) and (-1, -28): u = (-28 + 300) / 0.1, v = (-11 + 300) / 0.1 ...
    np.testing.assert_allclose(
        np.asarray(near["data"])[[0, -1]], [[2720.0, 2890.0], [2720.0, 2990.0]], atol=1e-6
    )
    assert set(_labels(out / "all_clips/scene-b/maps/map_labels.json")) == {"near-b"}
    assert set(_labels(out / f"site2clip/{SITE}_map_labels.json")) == {
        e.id for e in annotation_set().elements
    }


def test_site_round_trip(site: CamaReleaseResult) -> None:
    """The site map imports from the release root, from site2clip/ and from its file: every element back within
    one cell, lifted from the site raster; scene folders import in the site's frame too."""
    original = annotation_set()
    for path in (site.out, site.out / "site2clip", site.out / f"site2clip/{SITE}_map_labels.json"):
        back = import_cama(path)
        assert back.site_id == SITE and [e.id for e in back.elements] == [e.id for e in original.elements]
        for a, b in zip(original.elements, back.elements, strict=True):
            np.testing.assert_allclose(b.xy(), a.xy(), atol=1e-4)
    lifted = import_cama(site.out).by_id("near-a").xyz()
    assert lifted is not None
    np.testing.assert_allclose(lifted[:, 2], plane_z(lifted[:, 0], lifted[:, 1]), atol=1e-4)
    scene = import_cama(site.out / "all_clips/scene-a")
    np.testing.assert_allclose(scene.by_id("near-a").xy(), original.by_id("near-a").xy(), atol=1e-4)
    odometry = (site.out / "all_clips/scene-b/odometry/mcmv_camera_front.txt").read_text().splitlines()
    first = release_dataset().scene_by_name("scene-b").images["CAM_FRONT"][0]
    expected = lookup_camera_pose(first).translation - np.array([1021.0, 2030.0, 0.0])
    np.testing.assert_allclose(np.array(odometry[0].split()[1:4], dtype=float), expected, atol=2e-6)


def test_unobserved_cells_filled_from_nearest(tmp_path: Path) -> None:
    """Cells our raster did not observe (x > 40 m here) take the nearest observed value and are marked filled."""
    raster = plane_raster()
    raster[:, 141:] = np.nan  # columns beyond site x = -30 + 140 * 0.5 = 40
    result = export_release(tmp_path / "out", scenes=("scene-a",), elevation=raster)
    folder = result.out / "all_clips/scene-a/maps"
    elevation = np.load(folder / "vision_road_mlp_ft.npy")
    filled = cv2.imread(str(folder / "elevation_filled.png"), cv2.IMREAD_UNCHANGED)
    assert filled is not None and np.isfinite(elevation).all()
    v_obs, u_obs = round((10 - 21 + 150) / 0.1), round((2 + 150) / 0.1)  # site (10, 2)
    v_fill, u_fill = round((60 - 21 + 150) / 0.1), u_obs  # site (60, 2)
    assert filled[v_obs, u_obs] == 0 and filled[v_fill, u_fill] == 255
    assert elevation[v_fill, u_fill] == pytest.approx(float(plane_z(40.0, 2.0)), abs=0.01)


def test_without_raster_the_mean_element_height(tmp_path: Path) -> None:
    """No raster: every map is the lifted elements' mean z, all cells marked filled; no lift either: refused."""
    elements = annotation_set()
    mean_z = float(np.mean(np.concatenate([e.xyz()[:, 2] for e in elements.elements])))  # type: ignore[index]
    result = export_release(tmp_path / "out", scenes=("scene-b",), elevation=None)
    folder = result.out / "all_clips/scene-b/maps"
    elevation = np.load(folder / "vision_road_mlp_ft.npy")
    assert elevation.shape == (3000, 3000) and np.all(elevation == np.float32(mean_z))
    assert _sidecar(folder / "georeference.json")["elevation_source"] == "elements-mean"
    assert result.elevation_source == "elements-mean" and result.scenes[0].filled_cells == 3000 * 3000
    with pytest.raises(ValueError, match="elevation: no elevation raster given and no element is lifted"):
        export_release(tmp_path / "o2", elevation=None, annotations=annotation_set(lifted=False))


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"scenes": ("scene-a", "scene-x")}, r"scenes: \['scene-x'\] not in the data set"),
        ({"scenes": ("scene-a", "scene-a")}, r"scenes: repeated \['scene-a'\]"),
        ({"scenes": ()}, "scenes: expected a non-empty list"),
        ({"mode": "tile"}, "mode: expected one of"),
        ({"site_name": "a/b"}, "site_name: 'a/b' is not usable"),
        ({"observed_radius_m": 0.0}, "observed_radius_m: expected a finite value > 0"),
        ({"elevation": np.zeros((3, 3), np.float32)}, r"elevation: shape \(3, 3\) != the annotation set's"),
        ({"elevation": np.full((240, 240), np.nan, np.float32)}, "scene scene-a: no observed elevation cell"),
    ],
)
def test_bad_input_is_a_clear_error(tmp_path: Path, changes: dict, message: str) -> None:  # type: ignore[type-arg]
    """Each bad argument: a ValueError naming it."""
    with pytest.raises(ValueError, match=message):
        export_release(tmp_path / "out", **changes)


def test_import_names_what_to_pass(clip: CamaReleaseResult, tmp_path: Path) -> None:
    """A clip-mode release root has no site map: import says to pass a scene folder, listing them; a site2clip
    with several site maps says to pass one file."""
    with pytest.raises(ValueError, match=r"import one scene folder .*\['scene-a', 'scene-b'\]"):
        import_cama(clip.out)
    site2clip = tmp_path / "site2clip"
    site2clip.mkdir()
    for name in ("s1", "s2"):
        (site2clip / f"{name}_map_labels.json").write_text("[]")
    with pytest.raises(ValueError, match=r"site maps of \['s1', 's2'\]; pass one"):
        import_cama(tmp_path)


def test_default_radius_is_the_surface_ray_range() -> None:
    """The observed range's default radius is the surface stage's ray range (what the raster can hold)."""
    assert DEFAULT_OBSERVED_RADIUS_M == SurfaceConfig().max_range_m


def test_clipped_piece_lies_within_the_radius(clip: CamaReleaseResult) -> None:
    """Every exported point of scene-a lies within the observed radius of one of its cameras' trajectories."""
    dataset = release_dataset()
    tracks = [
        LineString([lookup_camera_pose(im).translation[:2] - np.array(SITE_ORIGIN) for im in images])
        for images in dataset.scene_by_name("scene-a").images.values()
    ]
    for element in import_cama(clip.out / "all_clips/scene-a").elements:
        for point in element.xy():
            distance = min(track.distance(LineString([point, point + 1e-9])) for track in tracks)
            assert distance <= RADIUS_M + 1e-3


def test_plain_release_site_map_imports(tmp_path: Path) -> None:
    """A release's site map without our sidecar lands in the release's world frame (its odometry's): [u, v] ->
    x = v * 0.1 - rows * 0.1 / 2, y = u * 0.1 - cols * 0.1 / 2; the site id is the file's."""
    site2clip = tmp_path / "site2clip"
    site2clip.mkdir()
    labels = [{"attrs": {"type": "Road_teeth"}, "data": [[10, 20], [110, 20]], "id": 5}]
    (site2clip / "bs_site01_map_labels.json").write_text(json.dumps(labels))
    np.save(site2clip / "bs_site01_vision_road_mlp_ft.npy", np.full((200, 300), 3.0, np.float32))
    (tmp_path / "site2clip.json").write_text(json.dumps({"bs_site01": ["scene-0001"]}))
    back = import_cama(tmp_path)
    assert back.site_id == "bs_site01"
    boundary = back.by_id("5")
    np.testing.assert_allclose(
        boundary.xy(), [[20 * 0.1 - 10, 10 * 0.1 - 15], [20 * 0.1 - 10, 110 * 0.1 - 15]]
    )
    xyz = boundary.xyz()
    assert xyz is not None and np.allclose(xyz[:, 2], 3.0)
    (site2clip / "bs_site01_vision_road_mlp_ft.npy").unlink()
    with pytest.raises(FileNotFoundError, match="bs_site01_vision_road_mlp_ft.npy: the site map's elevation"):
        import_cama(tmp_path)
