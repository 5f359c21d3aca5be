"""The in-process job runner: a thread pool owned by the app, a DB-backed context for progress and cancel.

A job row is the source of truth. The runner claims a queued row (queued -> running), calls the kind's function
with a `JobContext`, and records the outcome with a conditional UPDATE, so a cancel or a shutdown that marked
the row meanwhile is never overwritten. Cancellation is cooperative: `JobContext.report` reads the row's
`cancel_requested` flag and raises `JobCancelled`, which the runner turns into the `cancelled` state.
"""

import logging
import threading
import time
from collections.abc import Callable, Mapping
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pydantic import BaseModel
from sqlalchemy import select, update
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session, sessionmaker

from app.backend.clock import utc_now
from app.backend.errors import ConflictError
from app.backend.models_jobs import Job

logger = logging.getLogger(__name__)

DEFAULT_WORKERS = 2
REPORT_INTERVAL_S = 0.2
"""Least time between two progress writes (and cancel-flag reads) of one job, unless forced."""


class JobCancelled(Exception):
    """Raised inside a job function when its cancel was asked for or the server is shutting down."""


@dataclass(frozen=True)
class JobResult:
    """What a finished job leaves: the downloadable file (or None) and a one-line summary."""

    path: Path | None
    message: str


@dataclass(frozen=True)
class JobKind:
    """A runnable job kind: its parameter model (validated on submission), its function, and optionally its
    cleanup and a check of the params against the site at submission."""

    params: type[BaseModel]
    run: Callable[["JobContext", Any], JobResult]
    description: str
    cleanup: Callable[[Path], None] | None = None
    """Removes a job's intermediate files from its work folder (never its result): called when a job of the
    kind ends, however it ends, and on start for every job of the kind (what a killed server left)."""
    check: Callable[[Session, int, Any], None] | None = None
    """Refuses at submission, before the job is stored, what its params cannot do on this site (e.g. a
    refined-pose export of a site without a reconstruction): called with a session, the site id and the
    validated params; a ValueError whose message starts with `<field>: ` is a 422 naming that field."""


class JobContext:
    """What a job function sees: its ids, its work folder, short DB sessions, and progress reporting."""

    def __init__(
        self,
        *,
        job: Job,
        workdir: Path,
        sessions: sessionmaker[Session],
        stop: threading.Event,
        enqueue: Callable[[str, dict[str, Any], str], int] | None = None,
    ) -> None:
        self.job_id = job.id
        self.site_id = job.site_id
        self.workdir = workdir
        self._sessions = sessions
        self._stop = stop
        self._enqueue = enqueue
        self._last_report = 0.0

    def follow_up(self, kind: str, params: dict[str, Any]) -> int:
        """Queue another job of this site (e.g. a proposal refresh after a promotion); its id."""
        if self._enqueue is None:
            raise RuntimeError(f"job {self.job_id}: this context cannot queue follow-up jobs")
        return self._enqueue(kind, params, f"job {self.job_id}")

    def session(self) -> Session:
        """A new short-lived session (use it in a `with` block); the job holds none while it computes."""
        return self._sessions()

    def report(self, progress: float, message: str | None = None, *, force: bool = False) -> None:
        """Record progress in [0, 1] (throttled unless `force`); JobCancelled when a cancel was asked for."""
        if self._stop.is_set():
            raise JobCancelled("server shutting down")
        now = time.monotonic()
        if not force and now - self._last_report < REPORT_INTERVAL_S:
            return
        self._last_report = now
        values: dict[str, Any] = {"progress": min(max(float(progress), 0.0), 1.0), "updated_at": utc_now()}
        if message is not None:
            values["message"] = message
        with self._sessions() as session:
            session.execute(update(Job).where(Job.id == self.job_id, Job.state == "running").values(**values))
            cancel = session.scalar(select(Job.cancel_requested).where(Job.id == self.job_id))
            session.commit()
        if cancel:
            raise JobCancelled("cancel requested")


class JobRunner:
    """Runs submitted jobs on a small thread pool; create one per app and `shutdown()` it on app shutdown."""

    def __init__(
        self,
        *,
        sessions: sessionmaker[Session],
        data_dir: Path,
        kinds: Mapping[str, JobKind],
        unavailable: Mapping[str, str] | None = None,
        max_workers: int = DEFAULT_WORKERS,
    ) -> None:
        self.kinds = dict(kinds)
        """Runnable kinds by name; tests may add their own."""
        self.unavailable = dict(unavailable or {})
        """Known kinds this server cannot run, with the reason (e.g. retrain without a VMA registry)."""
        self._sessions = sessions
        self._jobs_dir = Path(data_dir).resolve() / "jobs"
        self._executor = ThreadPoolExecutor(max_workers=max_workers, thread_name_prefix="cama-job")
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self._submitted: set[int] = set()

    def workdir(self, job_id: int) -> Path:
        """The folder of one job's files: `<data_dir>/jobs/<id>/`."""
        return self._jobs_dir / str(job_id)

    def submit(self, job_id: int) -> None:
        """Queue a job row (state `queued`) for running."""
        with self._lock:
            self._submitted.add(job_id)
        self._executor.submit(self._run, job_id)

    def enqueue(
        self, session: Session, *, site_id: int, kind: str, params: dict[str, Any], username: str
    ) -> Job:
        """Store a job with already validated params as queued, commit, and submit it; ConflictError when the
        database refuses it (a second queued or running retrain of the site, from this process or another)."""
        now = utc_now()
        job = Job(
            site_id=site_id,
            kind=kind,
            params=params,
            state="queued",
            progress=0.0,
            message="queued",
            cancel_requested=False,
            created_by=username,
            created_at=now,
            updated_at=now,
        )
        session.add(job)
        try:
            session.commit()
        except IntegrityError:  # the partial unique index: one active retrain per site
            session.rollback()
            raise ConflictError(
                f"kind: a {kind} job of site {site_id} is already queued or running; wait for it or cancel it"
            ) from None
        self.submit(job.id)
        logger.info("job %d (%s) of site %d submitted by %s", job.id, kind, site_id, username)
        return job

    def _follow_up(self, site_id: int, kind: str, params: dict[str, Any], username: str) -> int:
        """Queue a job of a known kind from inside another job (params validated here)."""
        checked = self.kinds[kind].params.model_validate(params).model_dump(mode="json")
        with self._sessions() as session:
            return self.enqueue(session, site_id=site_id, kind=kind, params=checked, username=username).id

    def recover_interrupted(self) -> int:
        """Mark jobs left queued or running by a server that died (e.g. SIGKILL) as failed; call before serving.

        One runner owns a database's jobs, so at start-up no job can still be running elsewhere."""
        with self._sessions() as session:
            result = session.execute(
                update(Job)
                .where(Job.state.in_(("queued", "running")))
                .values(
                    state="failed",
                    message="interrupted: the server stopped before the job finished; submit it again",
                    finished_at=utc_now(),
                    updated_at=utc_now(),
                )
            )
            session.commit()
        count = int(getattr(result, "rowcount", 0) or 0)
        if count:
            logger.warning("%d job(s) interrupted by the previous server run marked failed", count)
        self.clean_up_workdirs()
        return count

    def clean_up_workdirs(self) -> int:
        """Run each kind's `cleanup` on the work folders of its jobs (at start: no job is running); how many
        folders were looked at."""
        with self._sessions() as session:
            jobs = session.execute(select(Job.id, Job.kind)).all()
        cleaned = 0
        for job_id, kind_name in jobs:
            kind = self.kinds.get(kind_name)
            workdir = self.workdir(job_id)
            if kind is not None and kind.cleanup is not None and workdir.is_dir():
                self._clean(kind, workdir)
                cleaned += 1
        return cleaned

    @staticmethod
    def _clean(kind: JobKind, workdir: Path) -> None:
        """A kind's cleanup of one folder; a failure is logged, never raised (the job's outcome stands)."""
        if kind.cleanup is None:
            return
        try:
            kind.cleanup(workdir)
        except OSError:
            logger.exception("cleaning up %s failed", workdir)

    def shutdown(self) -> None:
        """Stop running jobs at their next step, drop queued ones, and mark both failed as interrupted."""
        self._stop.set()
        self._executor.shutdown(wait=True, cancel_futures=True)
        with self._lock:
            ids = sorted(self._submitted)
        if not ids:
            return
        with self._sessions() as session:
            session.execute(
                update(Job)
                .where(Job.id.in_(ids), Job.state.in_(("queued", "running")))
                .values(state="failed", message="interrupted: server shut down", finished_at=utc_now())
            )
            session.commit()

    def _run(self, job_id: int) -> None:
        try:
            self._run_claimed(job_id)
        finally:
            with self._lock:
                self._submitted.discard(job_id)

    def _run_claimed(self, job_id: int) -> None:
        """Claim the job, run its kind and record the outcome."""
        with self._sessions() as session:
            claimed = session.execute(
                update(Job)
                .where(Job.id == job_id, Job.state == "queued")
                .values(state="running", started_at=utc_now(), updated_at=utc_now())
            )
            session.commit()
            job = session.get(Job, job_id)
        if job is None or getattr(claimed, "rowcount", 0) != 1:
            return  # cancelled (or gone) before it started
        kind = self.kinds[job.kind]
        workdir = self.workdir(job_id)
        workdir.mkdir(parents=True, exist_ok=True)
        site_id = job.site_id
        context = JobContext(
            job=job,
            workdir=workdir,
            sessions=self._sessions,
            stop=self._stop,
            enqueue=lambda kind, params, username: self._follow_up(site_id, kind, params, username),
        )
        logger.info("job %d (%s) of site %d started", job_id, job.kind, job.site_id)
        try:
            try:
                result = kind.run(context, kind.params.model_validate(job.params))
            finally:
                self._clean(kind, workdir)  # before the outcome is visible: a finished job is tidy
        except JobCancelled as reason:
            self._finish(job_id, state="cancelled", message=f"cancelled: {reason}")
        except Exception as error:
            logger.exception("job %d (%s) failed", job_id, job.kind)
            self._finish(job_id, state="failed", message=f"{type(error).__name__}: {error}")
        else:
            self._finish(
                job_id,
                state="succeeded",
                message=result.message,
                progress=1.0,
                result_path=None if result.path is None else str(result.path),
            )

    def _finish(self, job_id: int, *, state: str, message: str, **values: Any) -> None:
        """Record the outcome unless the row left `running` meanwhile (e.g. marked at shutdown)."""
        now = utc_now()
        with self._sessions() as session:
            session.execute(
                update(Job)
                .where(Job.id == job_id, Job.state == "running")
                .values(state=state, message=message[:4000], finished_at=now, updated_at=now, **values)
            )
            session.commit()
        logger.info("job %d %s: %s", job_id, state, message)
