"""Background jobs of a site: submit (leads), follow progress, cancel (leads), download the result."""

import logging
from typing import Annotated, Any

from fastapi import APIRouter, Query, Request, Response, status
from fastapi.responses import FileResponse

from app.backend.api.deps import MAX_ID, CurrentUser, IdPath, LeadUser, SessionDep, SettingsDep
from app.backend.crud import jobs
from app.backend.jobs.runner import JobRunner
from app.backend.schemas_jobs import JobCreate, JobKindPublic, JobPublic

logger = logging.getLogger(__name__)
router = APIRouter(tags=["jobs"])
CONFLICT: dict[int | str, dict[str, Any]] = {409: {"description": "The job has already finished."}}
STILL_RUNNING: dict[int | str, dict[str, Any]] = {409: {"description": "The job is queued or running."}}
ONE_RETRAIN: dict[int | str, dict[str, Any]] = {
    409: {"description": "A retrain of this site is already queued or running."}
}
DOWNLOAD: dict[int | str, dict[str, Any]] = {
    200: {"content": {"application/octet-stream": {}}, "description": "The job's result file."},
    404: {"description": "Unknown job, or no result yet (not succeeded)."},
}


def _runner(request: Request) -> JobRunner:
    runner: JobRunner = request.app.state.jobs
    return runner


@router.get("/job-kinds", response_model=list[JobKindPublic])
def list_job_kinds(request: Request, _user: CurrentUser) -> list[JobKindPublic]:
    """The job kinds this server knows: each runnable one with its params' JSON Schema (the export's formats
    and options among them), and the ones it cannot run with the reason."""
    return jobs.job_kinds(_runner(request))


@router.post(
    "/sites/{site_id}/jobs",
    response_model=JobPublic,
    status_code=status.HTTP_202_ACCEPTED,
    responses=ONE_RETRAIN,
)
def create_job(
    site_id: IdPath,
    job_in: JobCreate,
    request: Request,
    session: SessionDep,
    settings: SettingsDep,
    user: LeadUser,
) -> JobPublic:
    """Leads: queue a job (see `GET /api/job-kinds`); poll `GET /api/jobs/{id}` for its progress. An export's
    `dataset_root` must lie inside the server's data roots (CAMA_DATA_ROOTS); a refined-pose export of a site
    without a reconstruction is refused here (422 naming `poses`)."""
    job = jobs.create_job(
        session=session,
        runner=_runner(request),
        site_id=site_id,
        job_in=job_in,
        username=user.username,
        roots=settings.allowed_data_roots,
    )
    return jobs.job_public(job)


@router.get("/sites/{site_id}/jobs", response_model=list[JobPublic])
def list_jobs(
    site_id: IdPath,
    session: SessionDep,
    _user: CurrentUser,
    limit: Annotated[int, Query(ge=1, le=1000)] = 100,
    offset: Annotated[int, Query(ge=0, le=MAX_ID)] = 0,
) -> list[JobPublic]:
    """A site's jobs, newest first."""
    found = jobs.list_jobs(session=session, site_id=site_id, limit=limit, offset=offset)
    return [jobs.job_public(job) for job in found]


@router.get("/jobs/{job_id}", response_model=JobPublic)
def read_job(job_id: IdPath, session: SessionDep, _user: CurrentUser) -> JobPublic:
    """One job: state, progress in [0, 1] and message."""
    return jobs.job_public(jobs.get_job(session=session, job_id=job_id))


@router.post("/jobs/{job_id}/cancel", response_model=JobPublic, responses=CONFLICT)
def cancel_job(job_id: IdPath, session: SessionDep, _user: LeadUser) -> JobPublic:
    """Leads: cancel a queued job, or ask a running one to stop at its next step (state follows)."""
    return jobs.job_public(jobs.cancel_job(session=session, job_id=job_id))


@router.get("/jobs/{job_id}/download", response_class=FileResponse, responses=DOWNLOAD)
def download_job(job_id: IdPath, session: SessionDep, _user: CurrentUser) -> FileResponse:
    """The result of a succeeded job: `export.zip` of an export, `lifted.json` of a lift."""
    path = jobs.result_file(session=session, job_id=job_id)
    media = "application/zip" if path.suffix == ".zip" else "application/json"
    return FileResponse(path, media_type=media, filename=f"job-{job_id}-{path.name}")


@router.delete("/jobs/{job_id}", status_code=status.HTTP_204_NO_CONTENT, responses=STILL_RUNNING)
def delete_job(job_id: IdPath, request: Request, session: SessionDep, _user: LeadUser) -> Response:
    """Leads: remove a finished job and its files (the export it made included), to free disk space."""
    jobs.delete_job(session=session, runner=_runner(request), job_id=job_id)
    return Response(status_code=status.HTTP_204_NO_CONTENT)
