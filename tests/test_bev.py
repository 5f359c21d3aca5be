"""The BEV raster folder module: round trip, files byte-identical to the writers it replaced, georeference
transforms, and bad files rejected with the file and field named.

`tests/bev_fixture/` was written by the surface stage's previous raster writer (`write_rasters` with
`SurfaceGrid.georeference()`, before this module existed) from `_fixture_rasters()`; the generator's previous
writer gave the same bytes for the same arrays.
"""

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from cama_pipeline.bev import (
    GEOREFERENCE_FILE,
    LAYER_FILES,
    LAYER_NAMES,
    BevRasters,
    RasterGeoreference,
    is_raster_folder,
    present_layers,
    read_bev,
    read_georeference,
    read_layer,
    write_bev,
)

FIXTURE = Path(__file__).parent / "bev_fixture"
FILES = [*LAYER_FILES.values(), GEOREFERENCE_FILE]


def _fixture_rasters() -> BevRasters:
    """The arrays the fixture was written from (origin floats chosen to have long reprs)."""
    rng = np.random.default_rng(22)
    h, w = 5, 7
    semantic = rng.integers(0, 5, (h, w)).astype(np.uint8)
    semantic[0, :3] = 255
    rgb = rng.integers(0, 256, (h, w, 3)).astype(np.uint8)
    elevation = rng.normal(10.0, 0.3, (h, w)).astype(np.float32)
    elevation[0, :3] = np.nan
    count = rng.integers(0, 70000, (h, w)).clip(0, 65535).astype(np.uint16)
    count[0, :3] = 0
    geo = RasterGeoreference(
        origin_xy=(1000.0 / 3.0 + 1234.0, -987.25 - (0.1 + 0.2)), resolution=0.1, width=w, height=h
    )
    return BevRasters(geo, semantic, rgb, elevation, count)


def test_written_files_are_byte_identical_to_the_previous_writer(tmp_path: Path) -> None:
    write_bev(tmp_path, _fixture_rasters())
    for name in FILES:
        assert (tmp_path / name).read_bytes() == (FIXTURE / name).read_bytes(), name


def test_reading_the_previous_files_gives_the_same_arrays() -> None:
    expected, read = _fixture_rasters(), read_bev(FIXTURE)
    assert read.georeference == expected.georeference
    for name in LAYER_NAMES:
        np.testing.assert_array_equal(read.require(name), expected.require(name), err_msg=name)
        assert read.require(name).dtype == expected.require(name).dtype


def test_round_trip_of_some_layers(tmp_path: Path) -> None:
    full = _fixture_rasters()
    write_bev(
        tmp_path, BevRasters(full.georeference, semantic=full.semantic, photometric_rgb=full.photometric_rgb)
    )
    assert is_raster_folder(tmp_path)
    assert present_layers(tmp_path) == ("semantic", "photometric")
    back = read_bev(tmp_path, ("semantic", "photometric"))
    assert back.layers() == ("semantic", "photometric") and back.elevation is None
    np.testing.assert_array_equal(back.require("photometric"), full.photometric_rgb)
    with pytest.raises(FileNotFoundError, match="elevation.npy"):
        read_bev(tmp_path)
    with pytest.raises(ValueError, match="layer elevation: not in these rasters"):
        back.require("elevation")


def test_elevation_can_be_memory_mapped() -> None:
    elevation = read_layer(FIXTURE, "elevation", mmap=True)
    assert isinstance(elevation, np.memmap)
    np.testing.assert_array_equal(elevation, _fixture_rasters().elevation)


def test_an_interrupted_rewrite_leaves_the_folder_incomplete(tmp_path: Path, monkeypatch) -> None:
    rasters = _fixture_rasters()
    write_bev(tmp_path, rasters)
    monkeypatch.setattr("cama_pipeline.bev.atomic_write_npy", _fail)
    with pytest.raises(OSError, match="disk full"):
        write_bev(tmp_path, rasters)
    assert not is_raster_folder(tmp_path)


def _fail(*_args: object) -> None:
    raise OSError("disk full")


def test_georeference_transforms() -> None:
    geo = RasterGeoreference(origin_xy=(100.0, 50.0), resolution=0.5, width=8, height=6)
    assert geo.shape == (6, 8)
    np.testing.assert_allclose(
        geo.global_from_pixel([[0, 0], [2, 4], [7, 5]]), [[100, 50], [101, 48], [103.5, 47.5]]
    )
    np.testing.assert_allclose(geo.pixel_from_global([[101.0, 48.0, 9.0]]), [[2.0, 4.0]])  # z ignored
    np.testing.assert_allclose(geo.pixel_from_global(geo.global_from_pixel([[1.25, 3.5]])), [[1.25, 3.5]])
    assert geo.extent() == (100.0, 103.5, 47.5, 50.0)


@pytest.mark.parametrize(
    ("change", "field"),
    [
        ({"origin_xy": [0.0]}, "origin_xy"),
        ({"resolution": -0.1}, "resolution"),
        ({"resolution": None}, "resolution"),
        ({"width": None}, "width"),
        ({"row_axis": "+y"}, "row_axis"),
        ({"frame": "ego"}, "frame"),
        ({"resolutoin": 0.1}, "resolutoin"),
    ],
)
def test_bad_georeference_names_file_and_field(tmp_path: Path, change: dict, field: str) -> None:
    data = {**json.loads((FIXTURE / GEOREFERENCE_FILE).read_text()), **change}
    data = {key: value for key, value in data.items() if value is not None}
    (tmp_path / GEOREFERENCE_FILE).write_text(json.dumps(data))
    with pytest.raises(ValueError, match=rf"{GEOREFERENCE_FILE}: invalid raster georeference: .*{field}"):
        read_georeference(tmp_path)


def test_unreadable_files_are_named(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match=GEOREFERENCE_FILE):
        read_bev(tmp_path)
    shutil.copytree(FIXTURE, tmp_path, dirs_exist_ok=True)
    (tmp_path / GEOREFERENCE_FILE).write_text("{not json")
    with pytest.raises(ValueError, match=rf"{GEOREFERENCE_FILE}: not valid JSON"):
        read_bev(tmp_path)
    shutil.copy(FIXTURE / GEOREFERENCE_FILE, tmp_path)
    (tmp_path / "semantic.png").write_bytes(b"not a png")
    with pytest.raises(ValueError, match=r"semantic\.png: not a readable image"):
        read_bev(tmp_path)
    (tmp_path / "semantic.png").write_bytes((FIXTURE / "photometric.png").read_bytes())
    with pytest.raises(ValueError, match=r"semantic\.png: must be a single-channel 8-bit image"):
        read_bev(tmp_path)
    (tmp_path / "elevation.npy").write_bytes(b"\x93NUMPY broken")
    with pytest.raises(ValueError, match=r"elevation\.npy: not a readable \.npy raster"):
        read_bev(tmp_path, ["elevation"])


def test_rasters_that_do_not_fit_the_georeference(tmp_path: Path) -> None:
    shutil.copytree(FIXTURE, tmp_path, dirs_exist_ok=True)
    data = json.loads((tmp_path / GEOREFERENCE_FILE).read_text())
    (tmp_path / GEOREFERENCE_FILE).write_text(json.dumps({**data, "width": 9}))
    with pytest.raises(
        ValueError, match=r"georeference\.json: width x height 9 x 5 does not match .*semantic\.png"
    ):
        read_bev(tmp_path)
    rasters = _fixture_rasters()
    with pytest.raises(ValueError, match="does not match layer elevation"):
        BevRasters(rasters.georeference, elevation=np.zeros((2, 2), np.float32))
