"""Auth, roles, users and sites through the HTTP API."""

import json
import math
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from tests.backend.backend_helpers import PASSWORD, divider


def test_unauthenticated_is_401(client: TestClient, site_id: int) -> None:
    for method, path in [
        ("get", "/api/sites"),
        ("get", f"/api/sites/{site_id}/elements"),
        ("get", "/api/users"),
    ]:
        assert client.request(method, path).status_code == 401
    bad = {"Authorization": "Bearer not-a-token"}
    assert client.get("/api/sites", headers=bad).status_code == 401


def test_login_wrong_password_and_form(client: TestClient) -> None:
    assert client.post("/api/auth/login", json={"username": "root", "password": "nope"}).status_code == 401
    form = client.post(
        "/api/auth/login",
        content=f"username=root&password={PASSWORD.replace(' ', '+')}",
        headers={"Content-Type": "application/x-www-form-urlencoded"},
    )
    assert form.status_code == 200, form.text
    me = client.get("/api/auth/me", headers={"Authorization": f"Bearer {form.json()['access_token']}"})
    assert me.json()["role"] == "admin"
    assert client.post("/api/auth/login", json={"username": "root"}).status_code == 422


@pytest.mark.parametrize("role, expected", [("annotator", 403), ("lead", 403), ("admin", 201)])
def test_only_admin_creates_users(
    client: TestClient, headers: dict[str, dict[str, str]], role: str, expected: int
) -> None:
    body = {"username": f"new_{role}", "password": PASSWORD, "role": "annotator"}
    assert client.post("/api/users", json=body, headers=headers[role]).status_code == expected


def test_duplicate_user_is_409(client: TestClient, headers: dict[str, dict[str, str]]) -> None:
    body = {"username": "lead", "password": PASSWORD, "role": "lead"}
    assert client.post("/api/users", json=body, headers=headers["admin"]).status_code == 409


def test_annotator_cannot_register_site_or_bulk_load(
    client: TestClient, headers: dict[str, dict[str, str]], site_id: int, raster_dir: Path
) -> None:
    body = {"name": "x", "synthetic_dir": str(raster_dir)}
    assert client.post("/api/sites", json=body, headers=headers["annotator"]).status_code == 403
    bulk = {"elements": [divider(source="proposal", confidence=0.5)]}
    response = client.post(f"/api/sites/{site_id}/elements/bulk", json=bulk, headers=headers["annotator"])
    assert response.status_code == 403


def test_site_metadata(client: TestClient, headers: dict[str, dict[str, str]], site_id: int) -> None:
    client.post(f"/api/sites/{site_id}/elements", json=divider(), headers=headers["annotator"])
    sites = client.get("/api/sites", headers=headers["annotator"]).json()
    assert [s["id"] for s in sites] == [site_id]
    detail = client.get(f"/api/sites/{site_id}", headers=headers["annotator"]).json()
    extent = detail["extent"]
    assert math.isclose(extent["xmin"], -0.25) and math.isclose(extent["ymax"], 100.25)
    assert math.isclose(extent["xmax"], 99.75) and math.isclose(extent["ymin"], 0.25)
    assert {"semantic", "elevation"} <= set(detail["layers"])
    assert detail["counts_by_state"] == {"proposed": 1} and detail["counts_by_class"] == {"divider": 1}
    assert client.get("/api/sites/999", headers=headers["annotator"]).status_code == 404


def test_site_from_synthetic_folder(
    client: TestClient, headers: dict[str, dict[str, str]], tmp_path: Path
) -> None:
    folder = tmp_path / "synth"
    (folder / "ground_truth" / "bev").mkdir(parents=True)
    (folder / "manifest.json").write_text(json.dumps({"config": {"site_origin_xy": [5.0, 6.0]}}))
    geo = {"origin_xy": [5.0, 56.0], "resolution": 0.25, "width": 40, "height": 40}
    (folder / "ground_truth" / "bev" / "georeference.json").write_text(json.dumps(geo))
    response = client.post(
        "/api/sites", json={"name": "syn", "synthetic_dir": str(folder)}, headers=headers["lead"]
    )
    assert response.status_code == 201, response.text
    assert response.json()["site_origin_xy"] == [5.0, 6.0]
    missing = client.post(
        "/api/sites", json={"name": "bad", "synthetic_dir": str(tmp_path / "nope")}, headers=headers["lead"]
    )
    assert missing.status_code == 422 and "synthetic_dir" in missing.text
    again = client.post(
        "/api/sites", json={"name": "syn", "synthetic_dir": str(folder)}, headers=headers["lead"]
    )
    assert again.status_code == 409


def test_openapi_served(client: TestClient) -> None:
    schema = client.get("/openapi.json").json()
    assert "/api/sites/{site_id}/elements/{element_id}" in schema["paths"]
    assert client.get("/docs").status_code == 200
