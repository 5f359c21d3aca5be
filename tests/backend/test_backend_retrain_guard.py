"""One queued or running retrain per site, held by the database: a second server process on the same database
(its own engine, sessions and job runner) cannot add one, and an auto-retrain that loses that race starts none."""

import dataclasses
import threading
import time
from collections.abc import Iterator
from typing import Any

import pytest
from fastapi.testclient import TestClient
from pydantic import BaseModel
from sqlalchemy.orm import Session, sessionmaker

from app.backend import loop
from app.backend.config import Settings
from app.backend.db import make_engine, make_sessionmaker
from app.backend.errors import ConflictError
from app.backend.jobs.runner import JobContext, JobKind, JobResult, JobRunner
from app.backend.models_jobs import Job
from tests.backend.backend_helpers import divider

Headers = dict[str, dict[str, str]]


class _NoParams(BaseModel):
    """A stand-in retrain takes no parameters."""


@dataclasses.dataclass
class OtherProcess:
    """What a second server process on the same database has: its own sessions and job runner."""

    sessions: sessionmaker[Session]
    runner: JobRunner

    def enqueue_retrain(self, site_id: int) -> Job:
        with self.sessions() as session:
            return self.runner.enqueue(session, site_id=site_id, kind="retrain", params={}, username="other")


@pytest.fixture
def release(client: TestClient) -> Iterator[threading.Event]:
    """A stand-in `retrain` kind on the app that runs until the event is set."""
    event = threading.Event()

    def run(_context: JobContext, _params: Any) -> JobResult:
        event.wait(20.0)
        return JobResult(None, "stand-in retrain done")

    runner: JobRunner = client.app.state.jobs  # type: ignore[attr-defined]
    runner.kinds["retrain"] = JobKind(_NoParams, run, "stand-in")
    runner.unavailable.pop("retrain", None)
    yield event
    event.set()


@pytest.fixture
def other(client: TestClient, settings: Settings, release: threading.Event) -> Iterator[OtherProcess]:
    engine = make_engine(settings.resolved_database_url)
    kinds = dict(client.app.state.jobs.kinds)  # type: ignore[attr-defined]
    runner = JobRunner(sessions=make_sessionmaker(engine), data_dir=settings.data_dir / "other", kinds=kinds)
    yield OtherProcess(make_sessionmaker(engine), runner)
    release.set()
    runner.shutdown()
    engine.dispose()


def active_retrains(process: OtherProcess, site_id: int) -> int:
    with process.sessions() as session:
        jobs = session.query(Job).filter_by(site_id=site_id, kind="retrain")
        return sum(job.state in ("queued", "running") for job in jobs)


def wait_finished(client: TestClient, headers: Headers, job_id: int) -> str:
    deadline = time.monotonic() + 10.0
    while (state := client.get(f"/api/jobs/{job_id}", headers=headers["lead"]).json()["state"]) in (
        "queued",
        "running",
    ):
        assert time.monotonic() < deadline
        time.sleep(0.02)
    return str(state)


def test_a_second_process_cannot_queue_a_retrain_while_one_is_active(
    client: TestClient, headers: Headers, site_id: int, release: threading.Event, other: OtherProcess
) -> None:
    url = f"/api/sites/{site_id}/jobs"
    first = client.post(url, json={"kind": "retrain", "params": {}}, headers=headers["lead"])
    assert first.status_code == 202, first.text
    with pytest.raises(ConflictError, match="already queued or running"):
        other.enqueue_retrain(site_id)
    second = client.post(url, json={"kind": "retrain", "params": {}}, headers=headers["lead"])
    assert second.status_code == 409 and "already queued or running" in second.json()["detail"]
    assert active_retrains(other, site_id) == 1
    release.set()
    assert wait_finished(client, headers, first.json()["id"]) == "succeeded"
    assert other.enqueue_retrain(site_id).state == "queued"  # the site's turn is free again


def test_auto_retrain_that_loses_the_race_to_another_process_starts_none(
    client: TestClient,
    headers: Headers,
    site_id: int,
    settings: Settings,
    other: OtherProcess,
    make_element: Any,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    element = make_element(divider(10.0, 10.0))
    reviewed = client.post(
        f"/api/sites/{site_id}/elements/{element['id']}/review",
        json={"state": "accepted", "version": element["version"]},
        headers=headers["annotator"],
    )
    assert reviewed.status_code == 200, reviewed.text
    count = loop.new_corrections

    def count_while_another_process_starts_one(*args: Any) -> int:
        other.enqueue_retrain(site_id)  # lands between the auto-retrain's check and its insert
        return count(*args)

    monkeypatch.setattr(loop, "new_corrections", count_while_another_process_starts_one)
    runner: JobRunner = client.app.state.jobs  # type: ignore[attr-defined]
    with client.app.state.sessionmaker() as session:  # type: ignore[attr-defined]
        started = loop.maybe_retrain(
            session=session,
            runner=runner,
            settings=dataclasses.replace(settings, retrain_after=1),
            site_id=site_id,
        )
    assert started is None
    assert active_retrains(other, site_id) == 1
