"""Real-server helpers for system tests and the load bench: start `cama serve` on a free port, log in, seed a site."""

import json
import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx

ADMIN = "root"
PASSWORD = "correct horse battery"
ORIGIN_XY = (1000.0, 2000.0)
GEOREFERENCE = {"origin_xy": [1000.0, 2100.0], "resolution": 0.5, "width": 200, "height": 200}
"""Site extent in site metres: x [-0.25, 99.75], y [0.25, 100.25]."""
START_TIMEOUT_S = 90.0
"""Generous: under a loaded machine the `cama` entry point alone can take tens of seconds to import."""


def free_port() -> int:
    """A TCP port on loopback that nothing listens on right now."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def cama_executable() -> Path:
    """The `cama` console script of the running interpreter's environment."""
    path = Path(sys.executable).parent / "cama"
    if not path.exists():
        raise FileNotFoundError(f"{path}: the `cama` entry point is not installed in this environment")
    return path


@dataclass
class ServerProcess:
    """One `cama serve` process on loopback; `start()` blocks until the API answers."""

    data_dir: Path
    port: int = field(default_factory=free_port)
    database_url: str | None = None
    cpus: Sequence[int] | None = None
    """CPU cores the server may use (Linux affinity), e.g. (0, 1); None means all."""
    extra_env: dict[str, str] = field(default_factory=dict)
    """Environment variables added for the server (e.g. PYTHONPATH to serve other sources); CAMA_DATA_ROOTS
    defaults to the data folder's parent, where the tests put their site rasters."""
    process: subprocess.Popen[bytes] | None = None

    @property
    def base_url(self) -> str:
        """The server's root URL."""
        return f"http://127.0.0.1:{self.port}"

    def start(self) -> "ServerProcess":
        """Spawn the server with a bootstrap admin and wait until `/openapi.json` answers."""
        self.data_dir.mkdir(parents=True, exist_ok=True)
        env = {
            **os.environ,
            "CAMA_DATA_ROOTS": str(self.data_dir.resolve().parent),
            **self.extra_env,
            "CAMA_ADMIN_USERNAME": ADMIN,
            "CAMA_ADMIN_PASSWORD": PASSWORD,
        }
        command = [str(cama_executable()), "serve", str(self.data_dir), "--port", str(self.port)]
        if self.database_url:
            command += ["--database-url", self.database_url]
        cpus = set(self.cpus) if self.cpus else None
        log = (self.data_dir / "server.log").open("ab")
        self.process = subprocess.Popen(
            command,
            env=env,
            stdout=log,
            stderr=subprocess.STDOUT,
            preexec_fn=(lambda: os.sched_setaffinity(0, cpus)) if cpus else None,  # noqa: PLW1509
        )
        log.close()
        self._wait_ready()
        return self

    def _wait_ready(self) -> None:
        """Poll the OpenAPI document until it answers 200; RuntimeError with the log tail if the server dies."""
        deadline = time.monotonic() + START_TIMEOUT_S
        assert self.process is not None
        while time.monotonic() < deadline:
            if self.process.poll() is not None:
                raise RuntimeError(f"server exited with {self.process.returncode}:\n{self.log_tail()}")
            try:
                if httpx.get(f"{self.base_url}/openapi.json", timeout=1.0).status_code == 200:
                    return
            except httpx.TransportError:
                pass
            time.sleep(0.05)
        self.stop()
        raise RuntimeError(f"server did not answer within {START_TIMEOUT_S} s:\n{self.log_tail()}")

    def log_tail(self, n_chars: int = 4000) -> str:
        """The end of the server's log file."""
        path = self.data_dir / "server.log"
        return path.read_text(errors="replace")[-n_chars:] if path.exists() else ""

    def kill(self) -> None:
        """SIGKILL: no shutdown hooks, no flushing beyond what the database already made durable."""
        if self.process is not None and self.process.poll() is None:
            self.process.send_signal(signal.SIGKILL)
            self.process.wait(timeout=10)

    def stop(self) -> None:
        """SIGTERM and wait; SIGKILL if it does not exit."""
        if self.process is None or self.process.poll() is not None:
            return
        self.process.terminate()
        try:
            self.process.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.kill()


def login(client: httpx.Client, username: str = ADMIN, password: str = PASSWORD) -> dict[str, str]:
    """Authorization headers for a user."""
    response = client.post("/api/auth/login", json={"username": username, "password": password})
    if response.status_code != 200:
        raise RuntimeError(f"login {username}: {response.status_code} {response.text}")
    return {"Authorization": f"Bearer {response.json()['access_token']}"}


def register_site(client: httpx.Client, headers: dict[str, str], raster_dir: Path, name: str = "s1") -> int:
    """Register a 100 m x 100 m site from a hand-made raster folder (two empty layer files); its id."""
    raster_dir.mkdir(parents=True, exist_ok=True)
    for layer in ("semantic.png", "elevation.npy"):
        (raster_dir / layer).write_bytes(b"")
    (raster_dir / "georeference.json").write_text(json.dumps(GEOREFERENCE))
    body = {
        "name": name,
        "site_origin_xy": ORIGIN_XY,
        "georeference": GEOREFERENCE,
        "raster_dir": str(raster_dir),
    }
    response = client.post("/api/sites", json=body, headers=headers)
    if response.status_code != 201:
        raise RuntimeError(f"register site: {response.status_code} {response.text}")
    return int(response.json()["id"])


def divider_points(x0: float, y0: float) -> list[list[float]]:
    """A short three-vertex divider starting at (x0, y0), inside the site for 0 <= x0, y0 <= 80."""
    return [[x0, y0], [x0 + 5.0, y0], [x0 + 10.0, y0 + 1.0]]


def create_elements(client: httpx.Client, headers: dict[str, str], site_id: int, count: int) -> list[int]:
    """Create `count` dividers (version 1) and return their ids."""
    ids = []
    for index in range(count):
        body = {"class": "divider", "points": divider_points(5.0 + index % 60, 5.0 + index // 60)}
        response = client.post(f"/api/sites/{site_id}/elements", json=body, headers=headers)
        if response.status_code != 201:
            raise RuntimeError(f"create element: {response.status_code} {response.text}")
        ids.append(int(response.json()["id"]))
    return ids


def history(
    client: httpx.Client, headers: dict[str, str], site_id: int, element_id: int
) -> list[dict[str, Any]]:
    """An element's edit log, oldest first."""
    response = client.get(f"/api/sites/{site_id}/elements/{element_id}/history", headers=headers)
    response.raise_for_status()
    return list(response.json())
