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


def test_frontend_config_says_where_the_review_is(tmp_path: Path) -> None:
    settings = Settings(data_dir=tmp_path / "a", scrypt_n=2**4)
    with TestClient(create_app(settings)) as plain:
        assert plain.get("/api/frontend/config").json() == {"review_url": None, "review_site_id": None}
        paths = plain.get("/openapi.json").json()["paths"]
        assert "/api/frontend/config" in paths and "/" not in paths and "/assets/{name}" not in paths
    settings = Settings(data_dir=tmp_path / "b", scrypt_n=2**4, review_url=":8080", review_site_id=3)
    with TestClient(create_app(settings)) as linked:
        assert linked.get("/api/frontend/config").json() == {"review_url": ":8080", "review_site_id": 3}


@pytest.mark.parametrize("value", ["ftp://host/", "localhost:8080", "http://host:8080/?element=1", ":port"])
def test_a_bad_review_url_names_the_variable(value: str) -> None:
    with pytest.raises(ValueError, match="CAMA_REVIEW_URL"):
        Settings.from_env({"CAMA_REVIEW_URL": value})


def test_the_review_settings_come_from_the_environment() -> None:
    settings = Settings.from_env({"CAMA_REVIEW_URL": "http://10.0.0.5:8080/", "CAMA_REVIEW_SITE_ID": "2"})
    assert (settings.review_url, settings.review_site_id) == ("http://10.0.0.5:8080/", 2)
    with pytest.raises(ValueError, match="CAMA_REVIEW_SITE_ID"):
        Settings.from_env({"CAMA_REVIEW_SITE_ID": "0"})


def test_cama_serve_refuses_a_bad_review_url_before_serving(tmp_path: Path) -> None:
    from typer.testing import CliRunner

    from cama_studio.cli import app

    result = CliRunner().invoke(app, ["serve", str(tmp_path / "data"), "--review-url", "localhost:8080"])
    assert result.exit_code == 2
    assert "CAMA_REVIEW_URL" in result.output


def test_api_docs_load_swagger_ui_from_this_server_not_a_cdn(client: TestClient, dist: Path) -> None:
    (dist / "docs").mkdir()
    (dist / "docs" / "swagger-ui-bundle.js").write_text("window.SwaggerUIBundle = () => {};")
    page = client.get("/docs")
    assert page.status_code == 200 and "/openapi.json" in page.text
    assert "/docs/swagger-ui-bundle.js" in page.text and "/docs/swagger-ui.css" in page.text
    assert "http://" not in page.text and "https://" not in page.text, page.text
    assert client.get("/docs/swagger-ui-bundle.js").status_code == 200
    assert client.get("/docs/swagger-ui.css").status_code == 404  # not built here: 404, never elsewhere
    assert client.get("/docs/..%2F..%2Fsecret.txt").status_code == 404
    assert client.get("/redoc").status_code == 404  # ReDoc would come from a CDN: not served


def test_the_build_ships_swagger_ui() -> None:
    """The Vite build copies the files `/docs` serves (the setup step builds before the tests run)."""
    for name in frontend.DOCS_ASSETS:
        assert (frontend.DIST_DIR / "docs" / name).is_file(), (
            f"{name}: run `make setup` (npm ci + vite build)"
        )
