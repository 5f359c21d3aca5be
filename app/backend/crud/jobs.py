"""Jobs: submit (validating kind and params), read, list, cancel, and find the downloadable result."""

import logging
import shutil
from collections.abc import Sequence
from pathlib import Path

from pydantic import BaseModel, ValidationError
from sqlalchemy import select, update
from sqlalchemy.orm import Session

from app.backend.clock import utc_now
from app.backend.crud.sites import get_site
from app.backend.data_roots import ROOTS_CONTEXT
from app.backend.errors import ConflictError, InvalidInputError, NotFoundError
from app.backend.jobs.runner import JobRunner
from app.backend.models_jobs import FINISHED_STATES, Job
from app.backend.schemas_jobs import JobCreate, JobKindPublic, JobPublic

logger = logging.getLogger(__name__)


def job_public(job: Job) -> JobPublic:
    """The API view of a job."""
    view = JobPublic.model_validate({**{c: getattr(job, c) for c in _COLUMNS}, "download_url": None})
    if job.state == "succeeded" and job.result_path:
        view.download_url = f"/api/jobs/{job.id}/download"
    return view


_COLUMNS = tuple(name for name in JobPublic.model_fields if name != "download_url")


def job_kinds(runner: JobRunner) -> list[JobKindPublic]:
    """Every kind this server knows, runnable ones with their params' JSON Schema, by name."""
    views = [
        JobKindPublic(
            kind=name,
            description=kind.description,
            available=True,
            params_schema=kind.params.model_json_schema(),
        )
        for name, kind in runner.kinds.items()
    ]
    views += [
        JobKindPublic(kind=name, description=reason, available=False, reason=reason)
        for name, reason in runner.unavailable.items()
        if name not in runner.kinds
    ]
    return sorted(views, key=lambda view: view.kind)


def create_job(
    *,
    session: Session,
    runner: JobRunner,
    site_id: int,
    job_in: JobCreate,
    username: str,
    roots: Sequence[Path],
) -> Job:
    """Validate the kind and its params (folders must lie inside the data `roots`) and run the kind's check
    against the site, store the job as queued and hand it to the runner."""
    get_site(session=session, site_id=site_id)
    if job_in.kind in runner.unavailable:
        raise InvalidInputError("kind", f"{job_in.kind!r} is {runner.unavailable[job_in.kind]}")
    kind = runner.kinds.get(job_in.kind)
    if kind is None:
        known = sorted([*runner.kinds, *runner.unavailable])
        raise InvalidInputError("kind", f"unknown job kind {job_in.kind!r}; expected one of {known}")
    try:
        checked = kind.params.model_validate(job_in.params, context={ROOTS_CONTEXT: tuple(roots)})
    except ValidationError as error:
        raise InvalidInputError("params", _problems(error)) from None
    if kind.check is not None:
        try:
            kind.check(session, site_id, checked)
        except InvalidInputError:
            raise
        except ValueError as error:
            raise InvalidInputError(*_field_of(str(error), kind.params)) from None
    params = checked.model_dump(mode="json")
    return runner.enqueue(session, site_id=site_id, kind=job_in.kind, params=params, username=username)


def _field_of(message: str, params: type[BaseModel]) -> tuple[str, str]:
    """The field a check's message starts with (`<field>: ...`, a field of `params`) and the rest; `params`
    and the whole message otherwise."""
    field, separator, rest = message.partition(": ")
    return (field, rest) if separator and field in params.model_fields else ("params", message)


def _problems(error: ValidationError) -> str:
    """The params' validation errors by field, without the values given (they may be server paths)."""
    problems = []
    for item in error.errors(include_url=False, include_input=False, include_context=False):
        field = ".".join(str(part) for part in item["loc"]) or "params"
        message = str(item["msg"]).removeprefix("Value error, ")
        problems.append(message if message.startswith(f"{field}:") else f"{field}: {message}")
    return "; ".join(problems)


def get_job(*, session: Session, job_id: int) -> Job:
    """The job with this id; NotFoundError otherwise."""
    job = session.get(Job, job_id)
    if job is None:
        raise NotFoundError(f"job {job_id} not found")
    return job


def list_jobs(*, session: Session, site_id: int, limit: int, offset: int) -> list[Job]:
    """A site's jobs, newest first."""
    get_site(session=session, site_id=site_id)
    query = select(Job).where(Job.site_id == site_id).order_by(Job.id.desc()).limit(limit).offset(offset)
    return list(session.scalars(query))


def cancel_job(*, session: Session, job_id: int) -> Job:
    """Cancel a queued job at once, or ask a running one to stop at its next step; ConflictError if finished."""
    job = get_job(session=session, job_id=job_id)
    if job.state in FINISHED_STATES:
        raise ConflictError(f"job {job_id} already {job.state}; only queued or running jobs can be cancelled")
    now = utc_now()
    session.execute(
        update(Job)
        .where(Job.id == job_id, Job.state == "queued")
        .values(state="cancelled", message="cancelled before it started", finished_at=now, updated_at=now)
    )
    session.execute(
        update(Job)
        .where(Job.id == job_id, Job.state == "running")
        .values(cancel_requested=True, updated_at=now)
    )
    session.commit()
    session.refresh(job)
    if job.state in ("succeeded", "failed"):
        raise ConflictError(f"job {job_id} already {job.state}; only queued or running jobs can be cancelled")
    logger.info("job %d: cancel requested (%s)", job_id, job.state)
    return job


def result_file(*, session: Session, job_id: int) -> Path:
    """The file a succeeded job left; NotFoundError until it exists."""
    job = get_job(session=session, job_id=job_id)
    if job.state != "succeeded" or not job.result_path:
        raise NotFoundError(f"job {job_id} has no result to download (state {job.state})")
    path = Path(job.result_path)
    if not path.is_file():
        raise NotFoundError(f"job {job_id}: result file {path.name} is gone")
    return path


def delete_job(*, session: Session, runner: JobRunner, job_id: int) -> None:
    """Remove a finished job's row and its files (results included); ConflictError while it is queued or running."""
    job = get_job(session=session, job_id=job_id)
    if job.state not in FINISHED_STATES:
        raise ConflictError(f"job {job_id} is {job.state}; cancel it and wait until it has stopped")
    session.delete(job)
    session.commit()
    shutil.rmtree(runner.workdir(job_id), ignore_errors=True)
    logger.info("job %d deleted with its files", job_id)
