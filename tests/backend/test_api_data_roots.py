"""Server paths in requests come only from the configured data roots (issue 21.5): CAMA_DATA_ROOTS, default the
server's data folder; symlinks and `..` are resolved before the check."""

import json
import os
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from app.backend.config import Settings
from tests.backend.backend_helpers import GEOREFERENCE, ORIGIN_XY, PASSWORD

Headers = dict[str, dict[str, str]]


@pytest.fixture
def settings(tmp_path: Path, database_url: str | None) -> Settings:
    """No `data_roots`: the default, the data folder alone."""
    return Settings(
        data_dir=tmp_path / "data",
        database_url=database_url,
        scrypt_n=2**4,
        admin_username="root",
        admin_password=PASSWORD,
    )


def rasters(folder: Path) -> Path:
    folder.mkdir(parents=True)
    (folder / "georeference.json").write_text(json.dumps(GEOREFERENCE))
    return folder


def register(client: TestClient, lead: dict[str, str], folder: Path | str, name: str) -> int:
    body = {
        "name": name,
        "site_origin_xy": ORIGIN_XY,
        "georeference": GEOREFERENCE,
        "raster_dir": str(folder),
    }
    return client.post("/api/sites", json=body, headers=lead).status_code


def test_the_default_root_is_the_data_folder(
    client: TestClient, headers: Headers, settings: Settings, tmp_path: Path
) -> None:
    assert settings.allowed_data_roots == ((tmp_path / "data").resolve(),)
    inside = rasters(tmp_path / "data" / "sites" / "a")
    outside = rasters(tmp_path / "elsewhere")
    assert register(client, headers["lead"], inside, "inside") == 201
    assert register(client, headers["lead"], outside, "outside") == 422
    dotted = tmp_path / "data" / "sites" / ".." / ".." / "elsewhere"  # `..` out of the root
    assert register(client, headers["lead"], dotted, "dotted") == 422


def test_symlinks_are_resolved_before_the_check(client: TestClient, headers: Headers, tmp_path: Path) -> None:
    outside = rasters(tmp_path / "elsewhere")
    inside = rasters(tmp_path / "data" / "real")
    (tmp_path / "data" / "out-link").symlink_to(outside)
    (tmp_path / "data" / "in-link").symlink_to(inside)
    assert register(client, headers["lead"], tmp_path / "data" / "out-link", "out") == 422
    assert register(client, headers["lead"], tmp_path / "data" / "in-link", "in") == 201


def test_export_data_sets_must_lie_inside_the_roots_and_are_stored_resolved(
    client: TestClient, headers: Headers, tmp_path: Path
) -> None:
    site = rasters(tmp_path / "data" / "site")
    assert register(client, headers["lead"], site, "s") == 201
    site_id = client.get("/api/sites", headers=headers["lead"]).json()[0]["id"]

    def export(dataset_root: str) -> tuple[int, str]:
        params = {"format": "maptr", "poses": "coarse", "dataset_root": dataset_root}  # the site has no SfM
        body = {"kind": "export", "params": params}
        response = client.post(f"/api/sites/{site_id}/jobs", json=body, headers=headers["lead"])
        return response.status_code, response.text

    (tmp_path / "data" / "nuscenes").mkdir()
    code, text = export(str(tmp_path / "data" / "site" / ".." / "nuscenes"))
    assert code == 202 and json.loads(text)["params"]["dataset_root"] == str(
        (tmp_path / "data" / "nuscenes").resolve()
    )
    code, text = export(str(tmp_path))
    assert code == 422 and str(tmp_path) not in text, text


def test_roots_are_read_from_the_environment(tmp_path: Path) -> None:
    value = os.pathsep.join([str(tmp_path / "a"), str(tmp_path / "b")])
    settings = Settings.from_env({"CAMA_DATA_ROOTS": value, "CAMA_DATA_DIR": str(tmp_path / "data")})
    assert settings.data_roots == (tmp_path / "a", tmp_path / "b")
    assert settings.allowed_data_roots == ((tmp_path / "a").resolve(), (tmp_path / "b").resolve())
