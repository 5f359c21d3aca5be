"""Tile pyramids, layer colours, safe tile lookup and elevation queries on small hand-made rasters."""

import json
import os
from pathlib import Path

import cv2
import numpy as np
import pytest

from app.backend.tiles import (
    TileRequestError,
    UnknownLayerError,
    build_pyramid,
    build_site_pyramids,
    elevation_at,
    tile_file,
)
from app.backend.tiles.layers import (
    SEMANTIC_PALETTE_RGBA,
    count_bgra,
    elevation_bgra,
    layer_style,
    semantic_bgra,
)
from app.backend.tiles.pyramid import EMPTY_TILE_NAME, pyramid_levels, tile_path
from cama_pipeline.bev import RasterGeoreference

GEO = RasterGeoreference(origin_xy=(1000.0, 2000.0), resolution=0.5, width=600, height=300)


def _photometric(height: int = 300, width: int = 600) -> np.ndarray:
    """A smooth, non-constant RGB test image."""
    rows, cols = np.mgrid[0:height, 0:width]
    return np.stack([cols % 256, rows % 256, (rows + cols) % 256], axis=2).astype(np.uint8)


def _read_rgba_as_bgra(path: Path) -> np.ndarray:
    """A stored tile as OpenCV reads it (BGRA)."""
    tile = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    assert tile is not None and tile.shape[2] == 4
    return tile


def test_levels_and_tile_counts_for_600_by_300() -> None:
    levels = pyramid_levels(600, 300, 256)
    assert [(lv.width, lv.height, lv.cols, lv.rows) for lv in levels] == [
        (150, 75, 1, 1),
        (300, 150, 2, 1),
        (600, 300, 3, 2),
    ]
    assert [lv.z for lv in pyramid_levels(256, 10)] == [0]


def test_tiles_equal_downsampled_raster(tmp_path: Path) -> None:
    photo = _photometric()
    info = build_pyramid("photometric", photo, GEO, tmp_path)
    assert info.max_zoom == 2 and len(list((tmp_path / "photometric").rglob("*.png"))) == 9
    bgra = cv2.cvtColor(photo, cv2.COLOR_RGB2BGRA)
    finest = _read_rgba_as_bgra(tile_path(tmp_path, "photometric", 2, 2, 1))
    assert finest.shape == (256, 256, 4)  # the corner tile is padded, not cut, so no client stretches it
    np.testing.assert_array_equal(finest[:44, :88], bgra[256:300, 512:600])
    assert not finest[44:, :, 3].any() and not finest[:, 88:, 3].any()
    half = _read_rgba_as_bgra(tile_path(tmp_path, "photometric", 1, 0, 0))
    expected = cv2.resize(bgra[:, :512], (256, 150), interpolation=cv2.INTER_AREA)
    assert half.shape == (256, 256, 4) and not half[150:, :, 3].any()
    assert np.abs(half[:150].astype(int) - expected.astype(int)).max() <= 1


def test_semantic_palette_nearest_and_unobserved_transparent(tmp_path: Path) -> None:
    ids = np.full((300, 600), 255, dtype=np.uint8)
    ids[:, :300] = np.arange(300)[None, :] % 5
    build_pyramid("semantic", ids, GEO, tmp_path)
    tile = _read_rgba_as_bgra(tile_path(tmp_path, "semantic", 1, 0, 0))
    np.testing.assert_array_equal(tile[:150], semantic_bgra(ids[::2, :512:2]))
    r, g, b, a = SEMANTIC_PALETTE_RGBA[3]
    assert tuple(semantic_bgra(np.array([[3]], np.uint8))[0, 0]) == (b, g, r, a)
    assert semantic_bgra(np.array([[255]], np.uint8))[0, 0, 3] == 0
    assert not tile_path(tmp_path, "semantic", 2, 2, 0).exists()  # all unobserved: shared empty tile
    assert tile_file(tmp_path, "semantic", 2, 2, 0) == (tmp_path / EMPTY_TILE_NAME).resolve()


def test_elevation_colour_map_legend_and_nan() -> None:
    elevation = np.tile(np.linspace(0.0, 10.0, 101, dtype=np.float32), (5, 1))
    elevation[0, 0] = np.nan
    style = layer_style("elevation", elevation)
    assert style.legend.colormap == "viridis" and style.legend.unit == "m"
    assert style.legend.min == pytest.approx(np.nanpercentile(elevation, 2))
    assert style.legend.max == pytest.approx(np.nanpercentile(elevation, 98))
    bgra = elevation_bgra(np.array([[1.0, 9.0, np.nan]], np.float32), 1.0, 9.0)
    lut = cv2.applyColorMap(np.array([[0, 255]], np.uint8), cv2.COLORMAP_VIRIDIS)
    np.testing.assert_array_equal(bgra[0, :2, :3], lut[0])
    assert list(bgra[0, :, 3]) == [255, 255, 0]


def test_count_log_scale_and_zero_transparent() -> None:
    bgra = count_bgra(np.array([[0, 1, 99]], np.uint16), 99)
    lut = cv2.applyColorMap(np.array([[255]], np.uint8), cv2.COLORMAP_VIRIDIS)
    assert bgra[0, 0, 3] == 0 and bgra[0, 1, 3] == 255
    np.testing.assert_array_equal(bgra[0, 2, :3], lut[0, 0])
    assert layer_style("observation_count", np.array([[0, 7]], np.uint16)).legend.scale == "log"


def _write_bev(bev: Path, elevation: np.ndarray) -> None:
    """A minimal BEV directory: georeference, elevation and semantic layers."""
    bev.mkdir(parents=True, exist_ok=True)
    geo = {
        "origin_xy": [0.0, 0.0],
        "resolution": 1.0,
        "width": elevation.shape[1],
        "height": elevation.shape[0],
    }
    (bev / "georeference.json").write_text(json.dumps(geo))
    np.save(bev / "elevation.npy", elevation)
    cv2.imwrite(str(bev / "semantic.png"), np.ones(elevation.shape, np.uint8))


def test_rebuild_skipped_when_up_to_date_and_redone_on_change(tmp_path: Path) -> None:
    bev, cache = tmp_path / "bev", tmp_path / "cache"
    _write_bev(bev, np.zeros((40, 70), np.float32))
    first = build_site_pyramids(bev, cache)
    assert set(first) == {"semantic", "elevation"}
    info_file = cache / "elevation" / "pyramid.json"
    stamp = info_file.stat().st_mtime_ns
    assert build_site_pyramids(bev, cache) == first and info_file.stat().st_mtime_ns == stamp
    np.save(bev / "elevation.npy", np.full((40, 70), np.nan, np.float32))
    os.utime(bev / "elevation.npy", ns=(stamp + 10**9, stamp + 10**9))
    second = build_site_pyramids(bev, cache)
    assert second["elevation"].fingerprint != first["elevation"].fingerprint
    assert second["semantic"] == first["semantic"]
    assert not tile_path(cache, "elevation", 0, 0, 0).exists()  # all NaN now: the stale tile is gone


def test_array_fingerprint_detects_change(tmp_path: Path) -> None:
    ids = np.zeros((300, 600), np.uint8)
    first = build_pyramid("semantic", ids, GEO, tmp_path)
    assert build_pyramid("semantic", ids.copy(), GEO, tmp_path) == first
    ids[5, 5] = 3
    assert build_pyramid("semantic", ids, GEO, tmp_path).fingerprint != first.fingerprint


@pytest.mark.parametrize(
    ("layer", "z", "x", "y", "error"),
    [
        ("..", 0, 0, 0, UnknownLayerError),
        ("../semantic", 0, 0, 0, UnknownLayerError),
        ("elevation", 0, 0, 0, UnknownLayerError),  # known name, never built
        ("semantic", -1, 0, 0, TileRequestError),
        ("semantic", 0, -1, 0, TileRequestError),
        ("semantic", 3, 0, 0, TileRequestError),
        ("semantic", 2, 4, 0, TileRequestError),
        ("semantic", 1, 0, 2, TileRequestError),
        ("semantic", "..", 0, 0, TileRequestError),
        ("semantic", 1.0, 0, 0, TileRequestError),
        ("semantic", True, 0, 0, TileRequestError),
    ],
)
def test_tile_requests_rejected(
    tmp_path: Path, layer: str, z: object, x: object, y: object, error: type
) -> None:
    build_pyramid("semantic", np.ones((300, 600), np.uint8), GEO, tmp_path)
    with pytest.raises(error):
        tile_file(tmp_path, layer, z, x, y)  # type: ignore[arg-type]


def test_tile_file_inside_cache_and_beyond_raster_transparent(tmp_path: Path) -> None:
    build_pyramid("semantic", np.ones((300, 600), np.uint8), GEO, tmp_path)
    path = tile_file(tmp_path, "semantic", 2, 1, 1)
    assert path == tile_path(tmp_path.resolve(), "semantic", 2, 1, 1) and path.is_file()
    empty = tile_file(tmp_path, "semantic", 2, 3, 3)  # inside the 4 x 4 XYZ grid, beyond the raster
    assert empty.name == EMPTY_TILE_NAME and _read_rgba_as_bgra(empty)[:, :, 3].max() == 0


def test_elevation_at_plane_is_exact() -> None:
    geo = RasterGeoreference(origin_xy=(100.0, 50.0), resolution=0.25, width=8, height=6)
    rows, cols = np.mgrid[0:6, 0:8]
    gx, gy = 100.0 + cols * 0.25, 50.0 - rows * 0.25
    plane = (0.3 * gx - 0.2 * gy + 4.0).astype(np.float64)
    for x, y in [(100.0, 50.0), (100.6, 49.1), (101.75, 48.75), (101.1, 49.9)]:
        assert elevation_at(plane, geo, x, y) == pytest.approx(0.3 * x - 0.2 * y + 4.0, abs=1e-9)
    assert elevation_at(plane, geo, 99.9, 50.0) is None
    assert elevation_at(plane, geo, 100.0, 48.7) is None


def test_elevation_at_nan_gives_none_only_when_used() -> None:
    geo = RasterGeoreference(origin_xy=(0.0, 0.0), resolution=1.0, width=3, height=3)
    elevation = np.zeros((3, 3), np.float32)
    elevation[1, 1] = np.nan
    assert elevation_at(elevation, geo, 0.5, -0.5) is None
    assert elevation_at(elevation, geo, 0.0, 0.0) == 0.0
    assert elevation_at(elevation, geo, 2.0, -0.5) == 0.0
    with pytest.raises(ValueError):
        elevation_at(elevation, geo, float("nan"), 0.0)
