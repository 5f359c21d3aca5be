"""Export jobs leave only their archive (issue 21.7): the unzipped folder, the export's staging folder
(`.export.partial-<id>`, issue 24.9) and a half-written `export.zip.partial` are removed when the job ends, however
it ends, and on the next start after a server was killed mid-export."""

import time
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient

from app.backend.clock import utc_now
from app.backend.config import Settings
from app.backend.jobs import export
from app.backend.jobs.runner import JobContext
from app.backend.main import create_app
from app.backend.models_jobs import Job
from tests.backend.backend_helpers import divider

Headers = dict[str, dict[str, str]]
POLL_TIMEOUT_S = 10.0
EXPORT_PARAMS = {"format": "lanelet2", "origin_lat_lon": [1.299, 103.788]}


def run_export(client: TestClient, headers: Headers, site_id: int) -> tuple[dict[str, Any], Path]:
    """Submit a Lanelet2 export, wait for its end; the job and its work folder."""
    body = {"kind": "export", "params": EXPORT_PARAMS}
    job = client.post(f"/api/sites/{site_id}/jobs", json=body, headers=headers["lead"]).json()
    deadline = time.monotonic() + POLL_TIMEOUT_S
    while (done := client.get(f"/api/jobs/{job['id']}", headers=headers["lead"]).json())["state"] in (
        "queued",
        "running",
    ):
        assert time.monotonic() < deadline, done
        time.sleep(0.02)
    return done, client.app.state.jobs.workdir(job["id"])  # type: ignore[attr-defined]


def test_a_finished_export_keeps_only_its_zip(
    client: TestClient, headers: Headers, site_id: int, make_element: Any
) -> None:
    make_element(divider())
    done, workdir = run_export(client, headers, site_id)
    assert done["state"] == "succeeded", done["message"]
    assert sorted(path.name for path in workdir.iterdir()) == ["export.zip"]


def test_a_failed_export_leaves_nothing_half_written(
    client: TestClient, headers: Headers, site_id: int, make_element: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    make_element(divider())

    def broken_zip(folder: Path, archive: Path, context: JobContext) -> Path:
        archive.with_name(archive.name + ".partial").write_bytes(b"PK half")
        raise OSError("disk full")

    monkeypatch.setattr(export, "zip_folder", broken_zip)
    done, workdir = run_export(client, headers, site_id)
    assert done["state"] == "failed" and "disk full" in done["message"]
    assert list(workdir.iterdir()) == []


def test_leftovers_of_a_killed_export_are_removed_on_start(
    client: TestClient, settings: Settings, site_id: int
) -> None:
    with client.app.state.sessionmaker() as session:  # type: ignore[attr-defined]
        job = Job(
            site_id=site_id,
            kind="export",
            params=EXPORT_PARAMS,
            state="running",
            progress=0.9,
            message="packing the archive",
            cancel_requested=False,
            created_by="lead",
            created_at=utc_now(),
            updated_at=utc_now(),
        )
        session.add(job)
        session.commit()
        job_id = job.id
    workdir = client.app.state.jobs.workdir(job_id)  # type: ignore[attr-defined]
    (workdir / "export" / "maps").mkdir(parents=True)
    (workdir / "export" / "maps" / "map_labels.json").write_text("[]")
    (workdir / ".export.partial-0123456789ab" / "all_clips").mkdir(parents=True)
    (workdir / ".export.partial-0123456789ab" / "all_clips" / "odometry.txt").write_text("half")
    (workdir / ".export.old-0123456789ab").mkdir()
    (workdir / "export.zip.partial").write_bytes(b"PK half")
    restarted = create_app(settings)  # what `cama serve` does after a SIGKILL
    try:
        assert list(workdir.iterdir()) == []
        with restarted.state.sessionmaker() as session:
            assert session.get(Job, job_id).state == "failed"
    finally:
        restarted.state.engine.dispose()
