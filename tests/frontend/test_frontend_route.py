"""The backend serves the built editor at `/` with a strict CSP, its hashed assets, and nothing else."""

from collections.abc import Iterator
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from app.backend.api.routes import frontend
from app.backend.config import Settings
from app.backend.main import create_app


@pytest.fixture
def client(tmp_path: Path) -> Iterator[TestClient]:
    with TestClient(create_app(Settings(data_dir=tmp_path / "data", scrypt_n=2**4))) as test_client:
        yield test_client


@pytest.fixture
def dist(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A stand-in build output, so these tests do not depend on the Vite build."""
    folder = tmp_path / "dist"
    (folder / "assets").mkdir(parents=True)
    (folder / "index.html").write_text(
        '<!doctype html><script type="module" src="/assets/app-1.js"></script>'
    )
    (folder / "assets" / "app-1.js").write_text("console.log('editor')")
    (tmp_path / "secret.txt").write_text("not for the web")
    monkeypatch.setattr(frontend, "DIST_DIR", folder)
    return folder


def test_index_has_a_strict_content_security_policy(client: TestClient, dist: Path) -> None:
    response = client.get("/")
    assert response.status_code == 200
    assert response.headers["content-type"].startswith("text/html")
    policy = response.headers["content-security-policy"]
    assert (
        "script-src 'self'" in policy and "unsafe-inline" not in policy.split("script-src")[1].split(";")[0]
    )
    assert "/assets/app-1.js" in response.text


def test_assets_are_served_and_cached(client: TestClient, dist: Path) -> None:
    response = client.get("/assets/app-1.js")
    assert response.status_code == 200 and "editor" in response.text
    assert "immutable" in response.headers["cache-control"]


@pytest.mark.parametrize("name", ["..%2Fsecret.txt", "%2E%2E%2F%2E%2E%2Fsecret.txt", "missing.js"])
def test_nothing_outside_the_assets_is_served(client: TestClient, dist: Path, name: str) -> None:
    response = client.get(f"/assets/{name}")
    assert response.status_code == 404
    assert "not for the web" not in response.text


def test_missing_build_says_how_to_build(
    client: TestClient, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(frontend, "DIST_DIR", tmp_path / "nowhere")
    response = client.get("/")
    assert response.status_code == 404
    assert "make setup" in response.json()["detail"]


def test_api_routes_are_unaffected(client: TestClient, dist: Path) -> None:
    assert client.get("/api/sites").status_code == 401
    assert client.get("/openapi.json").status_code == 200
