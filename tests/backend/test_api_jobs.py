"""Background jobs through HTTP: lift and export run to completion, the export downloads, cancel, roles."""

import io
import json
import re
import threading
import time
import zipfile
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from fastapi.testclient import TestClient
from pydantic import BaseModel

from app.backend.clock import utc_now
from app.backend.config import Settings
from app.backend.jobs.runner import JobContext, JobKind, JobResult
from app.backend.main import create_app
from app.backend.models_jobs import Job
from tests.backend.backend_helpers import divider

Headers = dict[str, dict[str, str]]
POLL_TIMEOUT_S = 5.0
ORIGIN = [1.299, 103.788]


@pytest.fixture
def elevation_site(site_id: int, raster_dir: Path) -> int:
    """The conftest site with a 200 x 200 elevation plane whose top-left 20 x 20 cells are unobserved (NaN)."""
    rows, cols = np.mgrid[0:200, 0:200]
    elevation = (5.0 + 0.01 * cols + 0.02 * rows).astype(np.float32)
    elevation[:20, :20] = np.nan
    np.save(raster_dir / "elevation.npy", elevation)
    return site_id


def submit(client: TestClient, headers: Headers, site_id: int, kind: str, **params: Any) -> dict[str, Any]:
    response = client.post(
        f"/api/sites/{site_id}/jobs", json={"kind": kind, "params": params}, headers=headers["lead"]
    )
    assert response.status_code == 202, response.text
    return dict(response.json())


def wait_done(client: TestClient, headers: Headers, job_id: int) -> dict[str, Any]:
    deadline = time.monotonic() + POLL_TIMEOUT_S
    while time.monotonic() < deadline:
        job = client.get(f"/api/jobs/{job_id}", headers=headers["annotator"]).json()
        if job["state"] in ("succeeded", "failed", "cancelled"):
            return dict(job)
        time.sleep(0.02)
    raise AssertionError(f"job {job_id} still {job['state']} after {POLL_TIMEOUT_S} s")


def test_lift_job_lifts_live_elements_and_flags_unobserved_vertices(
    client: TestClient, headers: Headers, elevation_site: int, make_element: Any
) -> None:
    good = make_element(divider(10.0, 10.0))
    flagged = make_element(divider(1.0, 95.0))
    gone = make_element(divider(30.0, 30.0))
    deleted = client.delete(
        f"/api/sites/{elevation_site}/elements/{gone['id']}?version={gone['version']}",
        headers=headers["annotator"],
    )
    assert deleted.status_code in (200, 204), deleted.text
    job = submit(client, headers, elevation_site, "lift")
    assert job["state"] in ("queued", "running", "succeeded") and job["created_by"] == "lead"
    done = wait_done(client, headers, job["id"])
    assert done["state"] == "succeeded", done["message"]
    assert done["progress"] == 1.0
    assert "lifted 1 of 2 elements" in done["message"] and f"element {flagged['id']}" in done["message"]
    lifted = client.get(done["download_url"], headers=headers["annotator"])
    assert lifted.status_code == 200
    elements = {element["id"]: element for element in json.loads(lifted.content)["elements"]}
    assert set(elements) == {str(good["id"]), str(flagged["id"])}
    assert elements[str(flagged["id"])]["points_3d"] is None
    xyz = np.asarray(elements[str(good["id"])]["points_3d"])
    # site (10, 10) is raster col 20, row 180 on the plane 5 + 0.01 col + 0.02 row
    assert xyz[0] == pytest.approx([10.0, 10.0, 5.0 + 0.01 * 20 + 0.02 * 180], abs=1e-4)
    listed = client.get(f"/api/sites/{elevation_site}/jobs", headers=headers["annotator"])
    assert [item["id"] for item in listed.json()] == [job["id"]]


def test_export_job_downloads_a_zip(
    client: TestClient, headers: Headers, elevation_site: int, make_element: Any
) -> None:
    """A Lanelet2 export (no data set or poses needed; the formats that need them: test_api_export_*.py)."""
    made = make_element()
    job = submit(client, headers, elevation_site, "export", format="lanelet2", origin_lat_lon=ORIGIN)
    early = client.get(f"/api/jobs/{job['id']}/download", headers=headers["lead"])
    done = wait_done(client, headers, job["id"])
    assert early.status_code in (200, 404)
    assert done["state"] == "succeeded", done["message"]
    response = client.get(f"/api/jobs/{job['id']}/download", headers=headers["lead"])
    assert response.status_code == 200 and response.headers["content-type"] == "application/zip"
    with zipfile.ZipFile(io.BytesIO(response.content)) as bundle:
        assert bundle.namelist() == ["map.osm"]
        osm = bundle.read("map.osm").decode()
    assert f'k="cama:id" v="{made["id"]}"' in osm and 'k="cama:lifted" v="no"' not in osm
    assert "(lanelet2, 1 files, 1 of 1 lifted" in done["message"]  # heights from the site's elevation raster
    heights = {float(value) for value in re.findall(r'k="ele" v="([-0-9.e]+)"', osm)}
    # the divider (10, 10) .. (20, 11) in site metres lies on the plane 5 + 0.01 col + 0.02 row
    assert heights and all(8.0 < height < 9.0 for height in heights), heights


class _SlowParams(BaseModel):
    steps: int = 500


def test_cancel_stops_a_running_job_and_finished_jobs_conflict(
    client: TestClient, headers: Headers, site_id: int
) -> None:
    started = threading.Event()

    def slow(context: JobContext, params: _SlowParams) -> JobResult:
        for step in range(params.steps):
            started.set()
            context.report(step / params.steps, force=True)
            time.sleep(0.01)
        return JobResult(None, "ran to the end")

    client.app.state.jobs.kinds["slow"] = JobKind(_SlowParams, slow, "sleeps")  # type: ignore[attr-defined]
    job = submit(client, headers, site_id, "slow")
    assert started.wait(POLL_TIMEOUT_S)
    forbidden = client.post(f"/api/jobs/{job['id']}/cancel", headers=headers["annotator"])
    assert forbidden.status_code == 403
    cancel = client.post(f"/api/jobs/{job['id']}/cancel", headers=headers["lead"])
    assert cancel.status_code == 200, cancel.text
    assert cancel.json()["cancel_requested"] is True
    done = wait_done(client, headers, job["id"])
    assert done["state"] == "cancelled" and done["progress"] < 1.0
    assert client.get(f"/api/jobs/{job['id']}/download", headers=headers["lead"]).status_code == 404
    again = client.post(f"/api/jobs/{job['id']}/cancel", headers=headers["admin"])
    assert again.status_code == 409


def test_submission_rules(client: TestClient, headers: Headers, site_id: int) -> None:
    body = {"kind": "lift", "params": {}}
    annotator = client.post(f"/api/sites/{site_id}/jobs", json=body, headers=headers["annotator"])
    assert annotator.status_code == 403
    response = client.post(f"/api/sites/{site_id}/jobs", json={"kind": "retrain"}, headers=headers["lead"])
    assert response.status_code == 422  # no registry configured in these settings
    assert "no VMA checkpoint registry configured (set CAMA_VMA_REGISTRY)" in response.text
    learned = wait_done(
        client, headers, submit(client, headers, site_id, "refresh_proposals", proposer="learned")["id"]
    )
    assert learned["state"] == "failed" and "needs a VMA registry (CAMA_VMA_REGISTRY)" in learned["message"]
    unknown = client.post(f"/api/sites/{site_id}/jobs", json={"kind": "nope"}, headers=headers["lead"])
    assert unknown.status_code == 422 and "unknown job kind" in unknown.text
    bad = {"kind": "export", "params": {"format": "maptr"}}
    assert client.post(f"/api/sites/{site_id}/jobs", json=bad, headers=headers["lead"]).status_code == 422
    assert client.post("/api/sites/999/jobs", json=body, headers=headers["lead"]).status_code == 404
    assert client.get("/api/jobs/999", headers=headers["lead"]).status_code == 404
    assert client.post("/api/jobs/999/cancel", headers=headers["lead"]).status_code == 404
    assert client.get("/api/jobs/999/download", headers=headers["lead"]).status_code == 404


def test_lift_without_a_usable_elevation_raster_fails_with_the_file_named(
    client: TestClient, headers: Headers, site_id: int, make_element: Any
) -> None:
    make_element()
    done = wait_done(client, headers, submit(client, headers, site_id, "lift")["id"])
    assert done["state"] == "failed" and "elevation.npy" in done["message"]


def test_delete_removes_a_finished_job_and_its_files(
    client: TestClient, headers: Headers, elevation_site: int, make_element: Any
) -> None:
    make_element()
    job = submit(client, headers, elevation_site, "export", format="lanelet2", origin_lat_lon=ORIGIN)
    assert wait_done(client, headers, job["id"])["state"] == "succeeded"
    workdir = client.app.state.jobs.workdir(job["id"])  # type: ignore[attr-defined]
    assert any(workdir.iterdir())
    url = f"/api/jobs/{job['id']}"
    assert client.delete(url, headers=headers["annotator"]).status_code == 403
    assert client.delete(url, headers=headers["lead"]).status_code == 204
    assert not workdir.exists()
    assert client.get(url, headers=headers["lead"]).status_code == 404
    assert client.delete(url, headers=headers["lead"]).status_code == 404


def test_delete_refuses_a_running_job(client: TestClient, headers: Headers, site_id: int) -> None:
    release = threading.Event()

    def waits(context: JobContext, params: _SlowParams) -> JobResult:
        release.wait(POLL_TIMEOUT_S)
        return JobResult(None, "released")

    client.app.state.jobs.kinds["waits"] = JobKind(_SlowParams, waits, "waits")  # type: ignore[attr-defined]
    job = submit(client, headers, site_id, "waits")
    refused = client.delete(f"/api/jobs/{job['id']}", headers=headers["lead"])
    release.set()
    assert refused.status_code == 409 and "cancel it" in refused.json()["detail"]
    assert wait_done(client, headers, job["id"])["state"] == "succeeded"


def test_jobs_orphaned_by_a_crash_are_marked_failed_at_start(
    client: TestClient, headers: Headers, site_id: int, settings: Settings
) -> None:
    sessions = client.app.state.sessionmaker  # type: ignore[attr-defined]
    with sessions() as session:
        now = utc_now()
        orphan = Job(
            site_id=site_id,
            kind="export",
            params={},
            state="running",
            progress=0.4,
            message="running",
            cancel_requested=False,
            created_by="lead",
            created_at=now,
            updated_at=now,
        )
        session.add(orphan)
        session.commit()
        orphan_id = orphan.id
    with TestClient(create_app(settings)) as restarted:
        job = restarted.get(f"/api/jobs/{orphan_id}", headers=headers["lead"]).json()
    assert job["state"] == "failed" and "interrupted" in job["message"] and job["finished_at"]
