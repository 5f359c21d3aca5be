"""The 3D review following a backend: every element once, then idle polls that move no element data and stay out
of the request log, and a geometry edit, a review, a deletion and a new element drawn as they happen."""

import json
import logging
import socket
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import httpx
import numpy as np
import pytest
import viser
from fastapi.testclient import TestClient

from annotations.schema import Georeference
from app.backend.config import Settings
from app.backend.main import create_app
from app.viewer.content import Surface, local_frame_of
from app.viewer.review import follow, show_vectors
from app.viewer.scene import ReviewScene
from app.viewer.sources import ApiVectorSource
from cama_pipeline.bev import RasterGeoreference

PASSWORD = "correct horse battery"
SITE_ORIGIN_XY = (100.0, 200.0)
GEOREFERENCE = {"origin_xy": [100.05, 209.95], "resolution": 0.1, "width": 100, "height": 100}
"""Global x 100..110, y 200..210: site metres 0..10 in both."""


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def _flat_surface(z_m: float = 3.0) -> Surface:
    """The site's 10 m x 10 m at a constant height."""
    geo = Georeference.of(RasterGeoreference.from_json(GEOREFERENCE), site_origin_xy=(0.0, 0.0))
    return Surface(np.full(geo.shape, z_m), np.zeros(geo.shape, bool), geo, Path("."), True)


@pytest.fixture()
def backend(tmp_path: Path) -> Iterator[tuple[TestClient, dict[str, str], int]]:
    """An in-process backend (SQLite) with the site registered: (client, admin headers, site id)."""
    settings = Settings(
        data_dir=tmp_path / "data",
        data_roots=(tmp_path,),
        scrypt_n=2**4,
        admin_username="root",
        admin_password=PASSWORD,
    )
    rasters = tmp_path / "data" / "bev"  # inside the data folder: the server's only data root
    rasters.mkdir(parents=True)
    (rasters / "georeference.json").write_text(json.dumps(GEOREFERENCE))
    with TestClient(create_app(settings)) as client:
        login = client.post("/api/auth/login", json={"username": "root", "password": PASSWORD})
        headers = {"Authorization": f"Bearer {login.json()['access_token']}"}
        site = {
            "name": "flat",
            "site_origin_xy": SITE_ORIGIN_XY,
            "georeference": GEOREFERENCE,
            "raster_dir": str(rasters),
        }
        response = client.post("/api/sites", json=site, headers=headers)
        assert response.status_code == 201, response.text
        yield client, headers, int(response.json()["id"])
    client.app.state.engine.dispose()  # type: ignore[attr-defined]


def _wait_until(condition: Callable[[], bool], timeout_s: float = 10.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not condition():
        assert time.monotonic() < deadline, "the 3D review did not catch up"
        time.sleep(0.02)


def test_following_a_backend_moves_only_what_changed(
    backend: tuple[TestClient, dict[str, str], int], caplog: pytest.LogCaptureFixture
) -> None:
    client, headers, site_id = backend
    base = f"/api/sites/{site_id}/elements"

    def make(y: float) -> str:
        body = {"class": "divider", "points": [[2.0, y], [8.0, y]]}
        response = client.post(base, json=body, headers=headers)
        assert response.status_code == 201, response.text
        return str(response.json()["id"])

    moved, reviewed, removed = make(3.0), make(5.0), make(7.0)
    polls: list[httpx.Response] = []

    def record(response: httpx.Response) -> None:
        if response.request.url.path.endswith("/elements/changes"):
            response.read()
            polls.append(response)

    client.event_hooks["response"].append(record)
    server = viser.ViserServer(host="127.0.0.1", port=_free_port(), verbose=False)
    surface = _flat_surface()
    source = ApiVectorSource("http://testserver", site_id, "root", PASSWORD, client=client)
    scene = show_vectors(ReviewScene(server, local_frame_of(surface), surface), source)
    assert set(scene._vectors) == {moved, reviewed, removed}
    caplog.set_level(logging.INFO, logger="httpx")
    stop = threading.Event()
    worker = threading.Thread(target=follow, args=(scene, source, stop), kwargs={"interval_s": 0.02})
    worker.start()
    try:
        _wait_until(lambda: len(polls) >= 4)
        idle = polls[1:]
        assert all(p.json()["elements"] == [] and p.json()["deleted"] == [] for p in idle)
        assert max(len(p.content) for p in idle) < 64  # no element data
        assert not any("/elements/changes" in r.getMessage() for r in caplog.records if r.name == "httpx")

        edits = [
            client.patch(
                f"{base}/{moved}", json={"version": 1, "points": [[2.0, 4.0], [8.0, 4.0]]}, headers=headers
            ),
            client.post(
                f"{base}/{reviewed}/review", json={"state": "accepted", "version": 1}, headers=headers
            ),
            client.delete(f"{base}/{removed}", params={"version": 1}, headers=headers),
        ]
        assert all(edit.is_success for edit in edits), [edit.text for edit in edits]
        added = make(9.0)
        _wait_until(lambda: set(scene._vectors) == {moved, reviewed, added})
        _wait_until(lambda: scene._vectors[reviewed][0].state == "accepted")
        _wait_until(lambda: scene._vectors[moved][0].version == 2)
    finally:
        stop.set()
        worker.join(5)
        server.stop()
    y_m = scene._vectors[moved][0].points_xy[:, 1]
    assert np.allclose(y_m, SITE_ORIGIN_XY[1] + 4.0)  # the new geometry, in global metres
    later = [p.json() for p in polls[1:]]  # polls[0] read every element
    assert sorted(e["id"] for poll in later for e in poll["elements"]) == sorted(
        int(i) for i in (moved, reviewed, added)
    )
    assert [i for poll in later for i in poll["deleted"]] == [int(removed)]
