"""CAMA release layout: lossless export -> import, the type table, pixel convention, bad files, schema files."""

import json
from pathlib import Path

import numpy as np
import pytest
import typer
from typer.testing import CliRunner

from annotations import AnnotationSet, Georeference, MapElement, lift_element
from annotations.cama_format import (
    CAMA_TYPE_FROM_CLASS,
    MAP_LABELS,
    class_from_cama_type,
    export_cama,
    import_cama,
)
from annotations.poses import coarse_pose
from cama_pipeline.data import load_dataset
from cama_studio.export_command import SCHEMA_DIR, SCHEMA_MODELS, import_command, schema_text
from tests.annotations.annotation_helpers import SQUARE, element_kwargs, plane_z
from tests.data.nuscenes_fixture import write_nuscenes_fixture


def _set(georef: Georeference, elevation: np.ndarray) -> AnnotationSet:
    """A divider, a boundary and a closed crosswalk, lifted through the raster."""
    elements = [
        MapElement.model_validate(element_kwargs(id="d1", points_2d=[[1.0, 1.0], [5.0, 2.5], [10.0, 3.0]])),
        MapElement.model_validate(
            element_kwargs(id="b1", **{"class": "boundary"}, points_2d=[[2.0, 15.0], [18.0, 15.5]])
        ),
        MapElement.model_validate(
            element_kwargs(
                id="c1", **{"class": "ped_crossing"}, points_2d=[[x + 3, y + 5] for x, y in SQUARE]
            )
        ),
    ]
    lifted = [lift_element(e, elevation, georef) for e in elements]
    return AnnotationSet(site_id="site-a", georeference=georef, elements=lifted)


@pytest.fixture()
def raster(plane_elevation: np.ndarray) -> np.ndarray:
    """The plane raster as exported (float32)."""
    return plane_elevation.astype(np.float32)


def test_export_import_is_lossless(tmp_path: Path, georef: Georeference, raster: np.ndarray) -> None:
    """2D points, class, id and 3D points (z from the raster) come back within 1e-6 m."""
    original = _set(georef, raster)
    folder = export_cama(original, tmp_path, elevation=raster)
    assert folder == tmp_path / "site-a"
    assert {p.name for p in (folder / "maps").iterdir()} == {
        "map_labels.json",
        "elevation.npy",
        "georeference.json",
    }
    back = import_cama(folder)
    assert back.site_id == "site-a" and back.georeference == georef
    assert [e.id for e in back.elements] == ["d1", "b1", "c1"]
    for a, b in zip(original.elements, back.elements, strict=True):
        assert a.cls == b.cls
        np.testing.assert_allclose(b.xy(), a.xy(), atol=1e-6)
        assert a.points_3d is not None and b.points_3d is not None
        np.testing.assert_allclose(b.xyz(), a.xyz(), atol=1e-6)
    assert back.by_id("c1").closed and back.by_id("c1").points_2d[0] == back.by_id("c1").points_2d[-1]


def test_type_table_both_ways() -> None:
    """divider <-> lane_marking, boundary <-> Road_teeth, ped_crossing <-> Crosswalk_Line; Stop_Line optional."""
    assert CAMA_TYPE_FROM_CLASS == {
        "divider": "lane_marking",
        "boundary": "Road_teeth",
        "ped_crossing": "Crosswalk_Line",
    }
    for ours, cama in CAMA_TYPE_FROM_CLASS.items():
        assert class_from_cama_type(cama) == ours
    assert class_from_cama_type("Stop_Line") is None
    assert class_from_cama_type("Stop_Line", stop_line_as_divider=True) == "divider"
    with pytest.raises(ValueError, match="unknown CAMA type 'Foo'"):
        class_from_cama_type("Foo")


def test_pixel_convention(tmp_path: Path, georef: Georeference) -> None:
    """u = column (+x), v = row (-y): site (1.0, 19.0) is pixel (2, 2) when pixel (0, 0) is at site (0, 20)."""
    element = MapElement.model_validate(element_kwargs(points_2d=[[0.0, 20.0], [1.0, 19.0]]))
    folder = export_cama(AnnotationSet(site_id="s", georeference=georef, elements=[element]), tmp_path)
    labels = json.loads((folder / MAP_LABELS).read_text())
    assert labels[0]["data"] == [[0.0, 0.0], [2.0, 2.0]]
    assert labels[0]["attrs"] == {"type": "lane_marking"}
    assert labels[0]["shape_type"] == "polyline" and labels[0]["struct_type"] == "parsing"
    assert labels[0]["point_attrs"] == [[], []]
    assert import_cama(folder).elements[0].points_3d is None  # no raster exported, nothing lifted


def test_stop_line_skipped_unless_asked(tmp_path: Path, georef: Georeference, raster: np.ndarray) -> None:
    """A Stop_Line instance is skipped by default and imported as a divider on request."""
    folder = export_cama(_set(georef, raster), tmp_path, elevation=raster)
    labels = json.loads((folder / MAP_LABELS).read_text())
    labels.append({**labels[0], "id": 99, "attrs": {"type": "Stop_Line"}})
    (folder / MAP_LABELS).write_text(json.dumps(labels))
    assert len(import_cama(folder).elements) == 3
    stop = import_cama(folder, stop_line_as_divider=True).by_id("99")
    assert stop.cls == "divider"


@pytest.mark.parametrize(
    ("edit", "expected"),
    [
        (
            lambda labels: labels[2]["attrs"].update(type="Foo"),
            "map_labels.json: [2].attrs.type: unknown type 'Foo'",
        ),
        (
            lambda labels: labels[0]["data"][1].__setitem__(0, float("nan")),
            "map_labels.json: [0].data[1][0]: ",
        ),
        (lambda labels: labels[1].pop("attrs"), "map_labels.json: [1].attrs: Field required"),
        (lambda labels: labels.__setitem__(slice(None), []) or labels.append("x"), "map_labels.json: [0]: "),
    ],
)
def test_bad_labels_name_file_and_field(
    tmp_path: Path, georef: Georeference, raster: np.ndarray, edit: object, expected: str
) -> None:
    """Unknown type, NaN, a missing field or a non-object instance: ValueError naming file and field path."""
    folder = export_cama(_set(georef, raster), tmp_path, elevation=raster)
    labels = json.loads((folder / MAP_LABELS).read_text())
    edit(labels)  # type: ignore[operator]
    (folder / MAP_LABELS).write_text(json.dumps(labels))
    with pytest.raises(ValueError) as caught:
        import_cama(folder)
    assert expected in str(caught.value)


def test_labels_not_a_list(tmp_path: Path, georef: Georeference, raster: np.ndarray) -> None:
    """A map_labels.json that is not a list is rejected at the root."""
    folder = export_cama(_set(georef, raster), tmp_path)
    (folder / MAP_LABELS).write_text(json.dumps({"instances": []}))
    with pytest.raises(ValueError, match=r"map_labels.json: \(root\): Input should be a valid list"):
        import_cama(folder)


def test_missing_georeference_named(tmp_path: Path) -> None:
    """A folder without maps/georeference.json names the missing file."""
    with pytest.raises(FileNotFoundError, match="georeference.json"):
        import_cama(tmp_path)


def test_odometry_tum_rows(tmp_path: Path, georef: Georeference) -> None:
    """With a data set, one TUM file per camera: `t x y z qx qy qz qw`, camera to global."""
    fixture = write_nuscenes_fixture(tmp_path / "nuscenes", n_samples=2, with_can=False, with_lidar=False)
    dataset = load_dataset(fixture.root)
    folder = export_cama(
        AnnotationSet(site_id="s", georeference=georef), tmp_path / "out", dataset=dataset, poses=coarse_pose
    )
    image = dataset.scenes[0].images["CAM_FRONT"][0]
    rows = [line.split() for line in (folder / "odometry/camera_CAM_FRONT.txt").read_text().splitlines()[1:]]
    assert len(rows) == len(dataset.scenes[0].images["CAM_FRONT"]) and all(len(r) == 8 for r in rows)
    pose = image.global_from_ego @ image.calibration.ego_from_cam
    first = np.array(rows[0], dtype=float)
    assert first[0] == pytest.approx(image.timestamp_us / 1e6)
    np.testing.assert_allclose(first[1:4], pose.translation, atol=1e-6)
    np.testing.assert_allclose(first[[7, 4, 5, 6]], pose.rotation, atol=1e-8)
    sources = json.loads((folder / "odometry/pose_sources.json").read_text())
    assert sources["camera_CAM_FRONT.txt"] == {
        "counts": {"coarse": len(rows)},
        "rows": ["coarse"] * len(rows),
    }


def test_odometry_needs_a_pose_lookup(tmp_path: Path, georef: Georeference) -> None:
    """With a data set but no pose lookup, nothing silently falls back to the logged poses."""
    fixture = write_nuscenes_fixture(tmp_path / "nuscenes", n_samples=2, with_can=False, with_lidar=False)
    with pytest.raises(ValueError, match="no pose lookup"):
        export_cama(
            AnnotationSet(site_id="s", georeference=georef),
            tmp_path / "o",
            dataset=load_dataset(fixture.root),
        )


@pytest.mark.parametrize("name", sorted(SCHEMA_MODELS))
def test_committed_schemas_match_models(name: str) -> None:
    """annotations/schemas/*.schema.json equal the models' generated schemas (python -m cama_studio.export_command)."""
    assert (SCHEMA_DIR / name).read_text(encoding="utf-8") == schema_text(SCHEMA_MODELS[name])


RELEASE_ROWS, RELEASE_COLS = 200, 300  # 20 m x 30 m at 0.1 m: H/2 = 10 m, W/2 = 15 m
RELEASE_LABELS = [
    {"attrs": {"type": "lane_marking"}, "data": [[50, 40], [120, 40], [200, 60]], "id": 1},
    {"attrs": {"type": "Road_teeth"}, "data": [[10, 100], [290, 100]], "id": 2},
    {"attrs": {"type": "Crosswalk_Line"}, "data": [[100, 100], [140, 100], [140, 130], [100, 130]], "id": 3},
    {"attrs": {"type": "Stop_Line"}, "data": [[0, 0], [10, 0]], "id": 4},
]


def _release_plane(rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """The known plane at release pixels [v = row, u = col], in the release's world frame: x = v * 0.1 - H/2,
    y = u * 0.1 - W/2."""
    return plane_z(rows * 0.1 - RELEASE_ROWS * 0.1 / 2, cols * 0.1 - RELEASE_COLS * 0.1 / 2)


def _release_xy(uv: object, resolution_m: float = 0.1) -> np.ndarray:
    """Release pixels [u, v] in the release's world frame (metres)."""
    pixels = np.asarray(uv, dtype=float)
    half_h, half_w = RELEASE_ROWS * resolution_m / 2, RELEASE_COLS * resolution_m / 2
    return np.column_stack([pixels[:, 1] * resolution_m - half_h, pixels[:, 0] * resolution_m - half_w])


def _write_release(folder: Path, *, npy_name: str | None = "scene_height.npy") -> Path:
    """A plain CAMA release scene (no georeference.json): map_labels.json and, unless None, a plane raster."""
    (folder / "maps").mkdir(parents=True)
    (folder / MAP_LABELS).write_text(json.dumps(RELEASE_LABELS))
    if npy_name is not None:
        rows, cols = np.mgrid[0:RELEASE_ROWS, 0:RELEASE_COLS]
        elevation = _release_plane(rows, cols).astype(np.float32)
        elevation[180:, 280:] = np.nan  # an unobserved corner, away from the labels
        np.save(folder / "maps" / npy_name, elevation)
    return folder


def test_import_plain_release(tmp_path: Path) -> None:
    """The labels land in the release's world frame (its odometry's): pixel [u=50, v=40] is x = 40*0.1 - 10 = -6,
    y = 50*0.1 - 15 = -10; the georeference is that of the raster seen in our axes (transposed, rows flipped)."""
    back = import_cama(_write_release(tmp_path / "scene-0001"))
    assert back.site_id == "scene-0001"
    assert back.georeference == Georeference(
        site_origin_xy=(0.0, 0.0), origin_xy=(-10.0, 14.9), resolution=0.1, width=200, height=300
    )
    assert [(e.id, e.cls) for e in back.elements] == [
        ("1", "divider"),
        ("2", "boundary"),
        ("3", "ped_crossing"),
    ]
    divider = back.by_id("1")
    np.testing.assert_allclose(divider.points_2d[0], (-6.0, -10.0), atol=1e-9)
    np.testing.assert_allclose(divider.points_2d[2], (60 * 0.1 - 10, 200 * 0.1 - 15), atol=1e-9)
    for element, instance in zip(back.elements, RELEASE_LABELS, strict=False):
        data = np.asarray(instance["data"], dtype=float)
        np.testing.assert_allclose(element.xy()[: len(data)], _release_xy(data), atol=1e-9)
        xyz = element.xyz()
        assert xyz is not None
        np.testing.assert_allclose(xyz[:, 2], plane_z(xyz[:, 0], xyz[:, 1]), atol=1e-5)
    assert divider.points_3d is not None
    assert divider.points_3d[0][2] == pytest.approx(float(plane_z(-6.0, -10.0)), abs=1e-5)


def test_release_crosswalk_is_closed(tmp_path: Path) -> None:
    """An open Crosswalk_Line (first != last) is closed by appending its first point."""
    crossing = import_cama(_write_release(tmp_path / "s")).by_id("3")
    assert len(crossing.points_2d) == 5 and crossing.points_2d[0] == crossing.points_2d[-1]
    np.testing.assert_allclose(crossing.points_2d[0], (100 * 0.1 - 10, 100 * 0.1 - 15), atol=1e-9)


def test_release_stop_line_and_resolution(tmp_path: Path) -> None:
    """Stop_Line only on request; the resolution scales the frame (0.2 m: pixel [50, 40] -> (-12, -20))."""
    folder = _write_release(tmp_path / "s")
    back = import_cama(folder, stop_line_as_divider=True, resolution_m=0.2, site_id="site-x")
    assert back.site_id == "site-x" and back.by_id("4").cls == "divider"
    np.testing.assert_allclose(back.by_id("1").points_2d[0], _release_xy([[50, 40]], 0.2)[0], atol=1e-9)
    with pytest.raises(ValueError, match="resolution_m"):
        import_cama(folder, resolution_m=0.0)


def test_release_prefers_elevation_npy(tmp_path: Path) -> None:
    """elevation.npy wins over other .npy files; several others without it are ambiguous."""
    folder = _write_release(tmp_path / "s")
    np.save(folder / "maps/other.npy", np.zeros((10, 10)))
    with pytest.raises(ValueError, match=r"several \.npy files \['other.npy', 'scene_height.npy'\]"):
        import_cama(folder)
    (folder / "maps/scene_height.npy").rename(folder / "maps/elevation.npy")
    assert import_cama(folder).georeference.shape == (RELEASE_COLS, RELEASE_ROWS)  # seen in our axes


def test_release_without_raster_is_a_clear_error(tmp_path: Path) -> None:
    """No georeference.json and no .npy: FileNotFoundError naming the folder and what is needed."""
    folder = _write_release(tmp_path / "bare", npy_name=None)
    with pytest.raises(
        FileNotFoundError, match=r"bare: cannot place the CAMA labels: need .*georeference.json"
    ):
        import_cama(folder)


def test_release_import_command(tmp_path: Path) -> None:
    """`cama import --resolution-m` reads a plain release folder."""
    app = typer.Typer()
    app.command("import")(import_command)  # a one-command app: invoked without the command name
    folder = _write_release(tmp_path / "s")
    args = [str(folder), "--out", str(tmp_path / "a.json"), "--resolution-m", "0.2"]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 0, result.output
    np.testing.assert_allclose(
        AnnotationSet.read_json(tmp_path / "a.json").by_id("1").points_2d[0], (-12.0, -20.0)
    )
