"""Request bodies take no string or boolean for a number (integers still count as numbers), and every answer
carries `X-Content-Type-Options: nosniff` and, unless its route chose a cache policy, `Cache-Control: no-store`."""

from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient

from app.backend.api.routes import frontend
from tests.backend.backend_helpers import GEOREFERENCE, ORIGIN_XY, divider

Headers = dict[str, dict[str, str]]
MakeElement = Callable[..., dict[str, Any]]


@pytest.mark.parametrize(
    "points",
    [[[False, 0], [5, 0]], [[0, 0], [5, True]], [["1", 2], [6, 2]], [[1, 2], ["6", "2"]]],
)
def test_a_point_is_two_numbers(client: TestClient, headers: Headers, site_id: int, points: Any) -> None:
    body = {"class": "divider", "points": points}
    response = client.post(f"/api/sites/{site_id}/elements", json=body, headers=headers["annotator"])
    assert response.status_code == 422, response.text
    assert "points" in response.text


def test_integer_coordinates_are_numbers(client: TestClient, headers: Headers, site_id: int) -> None:
    body = {"class": "divider", "points": [[1, 2], [6, 2]], "confidence": 1, "source": "proposal"}
    response = client.post(f"/api/sites/{site_id}/elements", json=body, headers=headers["annotator"])
    assert response.status_code == 201, response.text
    assert response.json()["points"] == [[1.0, 2.0], [6.0, 2.0]] and response.json()["confidence"] == 1.0


@pytest.mark.parametrize("version", ["1", True, 1.5, None])
def test_a_version_is_an_integer(
    client: TestClient, headers: Headers, site_id: int, make_element: MakeElement, version: Any
) -> None:
    url = f"/api/sites/{site_id}/elements/{make_element()['id']}"
    who = headers["annotator"]
    assert client.patch(url, json={"version": version, "class": "boundary"}, headers=who).status_code == 422
    review = {"state": "accepted", "version": version}
    assert client.post(f"{url}/review", json=review, headers=who).status_code == 422
    restore = client.post(f"{url}/history/1/restore", json={"version": version}, headers=who)
    assert restore.status_code == 422
    assert client.get(url, headers=who).json()["version"] == 1


@pytest.mark.parametrize(
    "body",
    [
        {"elements": [divider(source="proposal", confidence=True)]},
        {"elements": [divider(source="proposal", confidence="0.5")]},
    ],
)
def test_a_confidence_is_a_number(client: TestClient, headers: Headers, site_id: int, body: Any) -> None:
    response = client.post(f"/api/sites/{site_id}/elements/bulk", json=body, headers=headers["lead"])
    assert response.status_code == 422, response.text


@pytest.mark.parametrize("lease_s", [True, "60"])
def test_a_lease_length_is_an_integer(
    client: TestClient, headers: Headers, site_id: int, lease_s: Any
) -> None:
    url = f"/api/sites/{site_id}/queue/next"
    assert client.post(url, json={"lease_s": lease_s}, headers=headers["annotator"]).status_code == 422


@pytest.mark.parametrize("field, value", [("width", "200"), ("height", True), ("resolution", "0.5")])
def test_a_georeference_is_numbers(
    client: TestClient, headers: Headers, raster_dir: Path, field: str, value: Any
) -> None:
    body = {
        "name": "strict",
        "site_origin_xy": ORIGIN_XY,
        "georeference": {**GEOREFERENCE, field: value},
        "raster_dir": str(raster_dir),
    }
    response = client.post("/api/sites", json=body, headers=headers["lead"])
    assert response.status_code == 422, response.text


def test_an_issue_element_id_is_an_integer(
    client: TestClient, headers: Headers, site_id: int, make_element: MakeElement
) -> None:
    body = {"reason": "other", "comment": "look", "element_id": str(make_element()["id"])}
    response = client.post(f"/api/sites/{site_id}/issues", json=body, headers=headers["lead"])
    assert response.status_code == 422, response.text


def assert_no_sniff_no_store(response: Any) -> None:
    assert response.headers["x-content-type-options"] == "nosniff", response.headers
    assert response.headers["cache-control"] == "no-store", response.headers


def test_every_api_answer_is_no_sniff_no_store(
    client: TestClient, headers: Headers, site_id: int, make_element: MakeElement
) -> None:
    who = headers["annotator"]
    no_work = client.post(f"/api/sites/{site_id}/queue/next", headers=who)  # the site has no element yet
    url = f"/api/sites/{site_id}/elements/{make_element()['id']}"
    answers = {
        200: client.get(url, headers=who),
        201: client.post(f"/api/sites/{site_id}/elements", json=divider(40, 40), headers=who),
        204: no_work,
        401: client.get("/api/auth/me"),
        403: client.get("/api/users", headers=who),
        404: client.get("/api/sites/999", headers=who),
        409: client.patch(url, json={"version": 9, "class": "boundary"}, headers=who),
        413: client.post(f"/api/sites/{site_id}/elements", content=b"x" * (65 * 1024), headers=who),
        422: client.patch(url, json={"version": "1"}, headers=who),
    }
    for status, response in answers.items():
        assert response.status_code == status, (status, response.text)
        assert_no_sniff_no_store(response)
    assert_no_sniff_no_store(client.post("/api/auth/login", json={"username": "root", "password": "x" * 9}))
    assert_no_sniff_no_store(client.get("/openapi.json"))


def test_editor_files_keep_their_cache_policy(
    client: TestClient, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    folder = tmp_path / "dist"
    (folder / "assets").mkdir(parents=True)
    (folder / "index.html").write_text("<!doctype html>")
    (folder / "assets" / "app-1.js").write_text("console.log('editor')")
    monkeypatch.setattr(frontend, "DIST_DIR", folder)
    page = client.get("/")
    assert page.headers["cache-control"] == "no-cache" and page.headers["x-content-type-options"] == "nosniff"
    asset = client.get("/assets/app-1.js")
    assert "immutable" in asset.headers["cache-control"]
    assert asset.headers["x-content-type-options"] == "nosniff"
    assert_no_sniff_no_store(client.get("/assets/missing.js"))
