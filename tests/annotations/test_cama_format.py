"""CAMA import and validation: the type table, older exports (sidecar version 1, one folder per site) read back,
bad labels in a release folder named by file and field, the committed schema files, and a plain CAMA release."""

import json
import os
import shutil
from pathlib import Path

import numpy as np
import pytest
import typer
from typer.testing import CliRunner

from annotations import AnnotationSet, Georeference
from annotations.cama_format import CAMA_TYPE_FROM_CLASS, MAP_LABELS, class_from_cama_type, import_cama
from cama_studio.export_command import SCHEMA_DIR, SCHEMA_MODELS, import_command, schema_text
from tests.annotations.annotation_helpers import plane_z
from tests.annotations.release_helpers import export_release

V1_LABELS = [
    {"attrs": {"type": "lane_marking"}, "data": [[0, 0], [2, 2], [20, 4]], "id": "d1"},
    {"attrs": {"type": "Road_teeth"}, "data": [[4, 10], [36, 11]], "id": "b1"},
    {"attrs": {"type": "Crosswalk_Line"}, "data": [[6, 22], [14, 22], [14, 30], [6, 30]], "id": "c1"},
]
"""Pixels of the `georef` fixture's raster (0.5 m, pixel (0, 0) at site (0, 20)): u = column (+x), v = row (-y)."""
V1_SITE_XY = {
    "d1": [(0.0, 20.0), (1.0, 19.0), (10.0, 18.0)],
    "b1": [(2.0, 15.0), (18.0, 14.5)],
    "c1": [(3.0, 9.0), (7.0, 9.0), (7.0, 5.0), (3.0, 5.0), (3.0, 9.0)],  # an open ring comes back closed
}


def _write_v1(folder: Path, elevation: np.ndarray | None) -> Path:
    """An older export's folder as that writer left it: labels, the version 1 sidecar and, if given, the raster."""
    (folder / "maps").mkdir(parents=True)
    (folder / "maps/map_labels.json").write_text(json.dumps(V1_LABELS))
    georeference = {
        "site_origin_xy": [100.0, 200.0],
        "origin_xy": [100.0, 220.0],
        "resolution": 0.5,
        "width": 40,
        "height": 40,
        "frame": "global",
        "row_axis": "-y",
        "col_axis": "+x",
    }
    sidecar = {
        "format": "cama-studio-georeference",
        "format_version": 1,
        "site_id": "site-a",
        "georeference": georeference,
    }
    (folder / "maps/georeference.json").write_text(json.dumps(sidecar, indent=2))
    if elevation is not None:
        np.save(folder / "maps/elevation.npy", elevation)
    return folder


def test_import_version_1_folder(tmp_path: Path, georef: Georeference, plane_elevation: np.ndarray) -> None:
    """An older export comes back in site metres through its stored georeference, with its site id, the classes,
    the crosswalk closed and z lifted from maps/elevation.npy."""
    back = import_cama(_write_v1(tmp_path / "site-a", plane_elevation.astype(np.float32)))
    assert back.site_id == "site-a" and back.georeference == georef
    assert [(e.id, e.cls) for e in back.elements] == [
        ("d1", "divider"),
        ("b1", "boundary"),
        ("c1", "ped_crossing"),
    ]
    for element in back.elements:
        assert element.source == "human" and element.review_state == "proposed"
        np.testing.assert_allclose(element.xy(), V1_SITE_XY[element.id], atol=1e-9)
        xyz = element.xyz()
        assert xyz is not None
        np.testing.assert_allclose(xyz[:, 2], plane_z(xyz[:, 0], xyz[:, 1]), atol=1e-5)
    assert back.by_id("c1").closed


def test_version_1_raster_optional_and_checked(tmp_path: Path) -> None:
    """Without maps/elevation.npy nothing is lifted; a raster of another shape than the georeference is refused,
    naming the file and both shapes."""
    assert all(e.points_3d is None for e in import_cama(_write_v1(tmp_path / "bare", None)).elements)
    folder = _write_v1(tmp_path / "wrong", np.zeros((10, 12), np.float32))
    with pytest.raises(ValueError, match=r"elevation.npy: shape \(10, 12\) != georeference .* \(40, 40\)"):
        import_cama(folder)


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


@pytest.fixture(scope="module")
def exported_scene(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """scene-a's folder of one clip-mode release export (`release_helpers`); tests edit a copy of it."""
    result = export_release(tmp_path_factory.mktemp("release") / "out", scenes=("scene-a",))
    return result.out / "all_clips/scene-a"


def _copy_or_link(src: str, dst: str) -> None:
    """JSON files are copied (the tests edit them); the rasters, which import only reads, are hard-linked."""
    if src.endswith(".json"):
        shutil.copy2(src, dst)
    else:
        os.link(src, dst)


@pytest.fixture()
def scene(exported_scene: Path, tmp_path: Path) -> Path:
    """A copy of the exported scene folder this test may edit."""
    return Path(shutil.copytree(exported_scene, tmp_path / "scene-a", copy_function=_copy_or_link))


def _edit_labels(folder: Path, edit: object) -> None:
    labels = json.loads((folder / MAP_LABELS).read_text())
    edit(labels)  # type: ignore[operator]
    (folder / MAP_LABELS).write_text(json.dumps(labels))


def test_stop_line_skipped_unless_asked(scene: Path) -> None:
    """A Stop_Line instance is skipped by default and imported as a divider on request."""
    count = len(import_cama(scene).elements)
    assert count == len(json.loads((scene / MAP_LABELS).read_text())) > 0
    _edit_labels(scene, lambda labels: labels.append({**labels[0], "id": 99, "attrs": {"type": "Stop_Line"}}))
    assert len(import_cama(scene).elements) == count
    assert import_cama(scene, stop_line_as_divider=True).by_id("99").cls == "divider"


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
def test_bad_labels_name_file_and_field(scene: Path, edit: object, expected: str) -> None:
    """Unknown type, NaN, a missing field or a non-object instance: ValueError naming file and field path."""
    _edit_labels(scene, edit)
    with pytest.raises(ValueError) as caught:
        import_cama(scene)
    assert expected in str(caught.value)


def test_labels_not_a_list(scene: Path) -> None:
    """A map_labels.json that is not a list is rejected at the root."""
    (scene / MAP_LABELS).write_text(json.dumps({"instances": []}))
    with pytest.raises(ValueError, match=r"map_labels.json: \(root\): Input should be a valid list"):
        import_cama(scene)


def test_missing_georeference_named(scene: Path, tmp_path: Path) -> None:
    """A folder without maps/georeference.json (or a raster) names the missing file; a sidecar without its
    georeference names the file and the field."""
    with pytest.raises(FileNotFoundError, match="georeference.json"):
        import_cama(tmp_path / "empty")
    sidecar = json.loads((scene / "maps/georeference.json").read_text())
    del sidecar["georeference"]
    (scene / "maps/georeference.json").write_text(json.dumps(sidecar))
    with pytest.raises(ValueError, match="georeference.json: georeference: Field required"):
        import_cama(scene)


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
