"""Raster endpoints through HTTP: layers with legends, cached tiles, traversal and bad indices, elevation."""

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from fastapi.testclient import TestClient

from app.backend.config import Settings
from tests.backend.backend_helpers import GEOREFERENCE, ORIGIN_XY, register_site

Headers = dict[str, dict[str, str]]
SLOPE_X, SLOPE_Y, BASE_M = 0.01, 0.02, 5.0
"""Elevation plane in raster pixels: BASE_M + SLOPE_X * col + SLOPE_Y * row."""


@pytest.fixture
def bev_dir(tmp_path: Path) -> Path:
    """A 200 x 200 BEV folder with every layer; elevation is a plane with an unobserved (NaN) corner."""
    folder = tmp_path / "bev_real"
    folder.mkdir()
    size = int(GEOREFERENCE["height"])  # type: ignore[call-overload]
    rows, cols = np.mgrid[0:size, 0:size]
    semantic = np.full((size, size), 1, np.uint8)
    semantic[:, 90:110] = 3
    cv2.imwrite(str(folder / "semantic.png"), semantic)
    cv2.imwrite(str(folder / "photometric.png"), np.dstack([semantic * 40] * 3).astype(np.uint8))
    cv2.imwrite(str(folder / "observation_count.png"), (rows % 7).astype(np.uint8))
    elevation = (BASE_M + SLOPE_X * cols + SLOPE_Y * rows).astype(np.float32)
    elevation[:20, :20] = np.nan
    np.save(folder / "elevation.npy", elevation)
    (folder / "georeference.json").write_text(json.dumps(GEOREFERENCE))
    return folder


@pytest.fixture
def raster_site(client: TestClient, headers: Headers, bev_dir: Path) -> int:
    """A site registered on the real raster folder."""
    return register_site(client, headers["lead"], bev_dir, "rasters")


def test_layers_list_every_layer_with_legend_and_build_once(
    client: TestClient, headers: Headers, raster_site: int, settings: Settings
) -> None:
    response = client.get(f"/api/sites/{raster_site}/layers", headers=headers["annotator"])
    assert response.status_code == 200, response.text
    layers = {layer["name"]: layer for layer in response.json()}
    assert set(layers) == {"semantic", "photometric", "elevation", "observation_count"}
    assert layers["semantic"]["pyramid"]["legend"]["kind"] == "categorical"
    assert layers["elevation"]["pyramid"]["legend"]["unit"] == "m"
    assert "{z}/{x}/{y}.png?v=" in layers["semantic"]["tile_url"]
    info = Path(settings.data_dir).resolve() / "tiles" / str(raster_site) / "semantic" / "pyramid.json"
    built_at = info.stat().st_mtime_ns
    again = client.get(f"/api/sites/{raster_site}/layers", headers=headers["lead"])
    assert again.json() == response.json()
    assert info.stat().st_mtime_ns == built_at


def test_tile_is_png_with_immutable_cache_and_etag(
    client: TestClient, headers: Headers, raster_site: int
) -> None:
    url = f"/api/sites/{raster_site}/tiles/semantic/0/0/0.png"
    response = client.get(url, headers=headers["annotator"])
    assert response.status_code == 200, response.text
    assert response.headers["content-type"] == "image/png"
    assert "immutable" in response.headers["cache-control"] and "private" in response.headers["cache-control"]
    assert response.headers["x-content-type-options"] == "nosniff"
    image = cv2.imdecode(np.frombuffer(response.content, np.uint8), cv2.IMREAD_UNCHANGED)
    assert image.shape[2] == 4 and max(image.shape[:2]) <= 256  # edge tiles are cut to the raster
    etag = response.headers["etag"]
    cached = client.get(url, headers={**headers["annotator"], "If-None-Match": etag})
    assert cached.status_code == 304
    other = client.get(f"/api/sites/{raster_site}/tiles/elevation/0/0/0.png", headers=headers["annotator"])
    assert other.status_code == 200 and other.headers["etag"] != etag


def test_tile_needs_auth(client: TestClient, raster_site: int) -> None:
    assert client.get(f"/api/sites/{raster_site}/tiles/semantic/0/0/0.png").status_code == 401


@pytest.mark.parametrize(
    "path",
    [
        "tiles/semantic/1/0/0.png",  # beyond max zoom (200 px fits in one tile)
        "tiles/semantic/0/1/0.png",
        "tiles/semantic/0/0/-1.png",
        "tiles/nosuchlayer/0/0/0.png",
        "tiles/..%2F..%2Fcama.db/0/0/0.png",
        "tiles/semantic/0/0/..%2F..%2F..%2Fcama.db",
        "tiles/%2E%2E/0/0/0.png",
        "tiles/semantic/0/0/0.png/../../../../cama.db",
    ],
)
def test_bad_tiles_are_404_or_422(client: TestClient, headers: Headers, raster_site: int, path: str) -> None:
    response = client.get(f"/api/sites/{raster_site}/{path}", headers=headers["annotator"])
    assert response.status_code in (404, 422), response.text
    assert response.headers.get("content-type", "").startswith("application/json")


def test_non_integer_tile_index_is_422(client: TestClient, headers: Headers, raster_site: int) -> None:
    response = client.get(f"/api/sites/{raster_site}/tiles/semantic/0/a/0.png", headers=headers["annotator"])
    assert response.status_code == 422


def test_tiles_of_unknown_site_404(client: TestClient, headers: Headers) -> None:
    assert (
        client.get("/api/sites/999/tiles/semantic/0/0/0.png", headers=headers["annotator"]).status_code == 404
    )
    assert client.get("/api/sites/999/layers", headers=headers["annotator"]).status_code == 404


def test_unreadable_rasters_are_422_not_500(client: TestClient, headers: Headers, site_id: int) -> None:
    response = client.get(f"/api/sites/{site_id}/layers", headers=headers["annotator"])  # empty layer files
    assert response.status_code == 422, response.text
    assert "raster" in response.text


def test_elevation_on_a_plane(client: TestClient, headers: Headers, raster_site: int) -> None:
    x, y = 30.25, 60.5
    response = client.get(
        f"/api/sites/{raster_site}/elevation", params={"x": x, "y": y}, headers=headers["annotator"]
    )
    assert response.status_code == 200, response.text
    body = response.json()
    col = (ORIGIN_XY[0] + x - GEOREFERENCE["origin_xy"][0]) / GEOREFERENCE["resolution"]  # type: ignore[index]
    row = (GEOREFERENCE["origin_xy"][1] - (ORIGIN_XY[1] + y)) / GEOREFERENCE["resolution"]  # type: ignore[index]
    assert body["elevation_m"] == pytest.approx(BASE_M + SLOPE_X * col + SLOPE_Y * row, abs=1e-4)
    assert body["global_xy"] == [ORIGIN_XY[0] + x, ORIGIN_XY[1] + y]


@pytest.mark.parametrize(("x", "y"), [(2.0, 98.0), (500.0, 50.0)])
def test_elevation_unobserved_or_outside_is_null(
    client: TestClient, headers: Headers, raster_site: int, x: float, y: float
) -> None:
    response = client.get(
        f"/api/sites/{raster_site}/elevation", params={"x": x, "y": y}, headers=headers["annotator"]
    )
    assert response.status_code == 200, response.text
    assert response.json()["elevation_m"] is None


@pytest.mark.parametrize(
    "params", [{"x": "nan", "y": "1"}, {"x": "1", "y": "inf"}, {"x": "a", "y": "1"}, {"x": "1"}]
)
def test_elevation_bad_query_is_422(
    client: TestClient, headers: Headers, raster_site: int, params: dict[str, str]
) -> None:
    response = client.get(f"/api/sites/{raster_site}/elevation", params=params, headers=headers["annotator"])
    assert response.status_code == 422, response.text
