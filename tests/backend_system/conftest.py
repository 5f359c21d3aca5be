"""System-test fixtures: a real `cama serve` process on a temporary data folder, a client, a seeded site."""

from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest

from tests.backend_system.system_helpers import ServerProcess, login, register_site


@pytest.fixture
def server(tmp_path: Path) -> Iterator[ServerProcess]:
    """A running server on a fresh SQLite database with the bootstrap admin; stopped afterwards."""
    process = ServerProcess(data_dir=tmp_path / "data").start()
    try:
        yield process
    finally:
        process.stop()


@pytest.fixture
def api(server: ServerProcess) -> Iterator[httpx.Client]:
    """An HTTP client on the server."""
    with httpx.Client(base_url=server.base_url, timeout=10.0) as client:
        yield client


@pytest.fixture
def admin_headers(api: httpx.Client) -> dict[str, str]:
    """The bootstrap admin's auth headers."""
    return login(api)


@pytest.fixture
def site_id(api: httpx.Client, admin_headers: dict[str, str], tmp_path: Path) -> int:
    """A registered 100 m x 100 m site."""
    return register_site(api, admin_headers, tmp_path / "bev")
