"""Backend test helpers: an app on a fresh database per test (SQLite, and PostgreSQL where its server programs
are installed), users per role, a small site."""

import json
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient

from app.backend.config import Settings
from app.backend.main import create_app
from tests.backend.backend_helpers import GEOREFERENCE, PASSWORD, divider, login, register_site
from tests.backend.postgres_server import PostgresServer, find_bin_dir
from tests.dependency_policy import missing


@pytest.fixture(scope="session")
def postgres() -> Iterator[PostgresServer]:
    """A PostgreSQL server for the session; skipped with the reason, or failed under CI, when not installed."""
    bin_dir = find_bin_dir()
    if bin_dir is None:
        missing(
            "PostgreSQL server programs (initdb, pg_ctl on PATH or in /usr/lib/postgresql/*/bin)",
            "`make test` installs them: its postgresql target installs Debian's postgresql package",
        )
    server = PostgresServer(bin_dir)
    server.start()
    yield server
    server.stop()


@pytest.fixture(params=["sqlite", "postgresql"])
def database_url(request: pytest.FixtureRequest) -> str | None:
    """Every backend test runs on both databases: None is the default SQLite file in the data folder."""
    if request.param == "sqlite":
        return None
    server: PostgresServer = request.getfixturevalue("postgres")
    return server.database_url()


@pytest.fixture
def settings(tmp_path: Path, database_url: str | None) -> Settings:
    """Settings on a temporary data folder with cheap password hashing and a small payload limit; request
    paths may lie anywhere in the test's temporary folder (the site rasters are beside the data folder)."""
    return Settings(
        data_dir=tmp_path / "data",
        data_roots=(tmp_path,),
        database_url=database_url,
        scrypt_n=2**4,
        max_payload_bytes=64 * 1024,
        extent_margin_m=10.0,
        admin_username="root",
        admin_password=PASSWORD,
    )


@pytest.fixture
def client(settings: Settings) -> Iterator[TestClient]:
    """A client on a freshly migrated database with a bootstrap admin."""
    with TestClient(create_app(settings)) as test_client:
        yield test_client
    test_client.app.state.engine.dispose()  # type: ignore[attr-defined]


@pytest.fixture
def headers(client: TestClient) -> dict[str, dict[str, str]]:
    """Auth headers by role: the bootstrap admin creates one annotator and one lead."""
    admin = login(client, "root")
    for role in ("annotator", "lead"):
        response = client.post(
            "/api/users", json={"username": role, "password": PASSWORD, "role": role}, headers=admin
        )
        assert response.status_code == 201, response.text
    return {"admin": admin, "annotator": login(client, "annotator"), "lead": login(client, "lead")}


@pytest.fixture
def raster_dir(tmp_path: Path) -> Path:
    """A raster folder with two (empty) layer files."""
    folder = tmp_path / "bev"
    folder.mkdir()
    for name in ("semantic.png", "elevation.npy"):
        (folder / name).write_bytes(b"")
    (folder / "georeference.json").write_text(json.dumps(GEOREFERENCE))
    return folder


@pytest.fixture
def site_id(client: TestClient, headers: dict[str, dict[str, str]], raster_dir: Path) -> int:
    """A registered site 100 m x 100 m."""
    return register_site(client, headers["lead"], raster_dir, "s1")


@pytest.fixture
def make_element(
    client: TestClient, headers: dict[str, dict[str, str]], site_id: int
) -> Callable[..., dict[str, Any]]:
    """Create an element as the annotator and return its JSON."""

    def make(body: dict[str, Any] | None = None) -> dict[str, Any]:
        response = client.post(
            f"/api/sites/{site_id}/elements", json=body or divider(), headers=headers["annotator"]
        )
        assert response.status_code == 201, response.text
        return dict(response.json())

    return make
