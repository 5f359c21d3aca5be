"""API shapes for background jobs: a submission (kind + params) and the public view of a job."""

import logging
from datetime import datetime
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field

from app.backend.schemas import STRICT

logger = logging.getLogger(__name__)

JobState = Literal["queued", "running", "succeeded", "failed", "cancelled"]


class JobCreate(BaseModel):
    """A job to run on a site: `lift` or `export` (retrain and refresh_proposals need the VMA model)."""

    model_config = STRICT
    kind: str = Field(min_length=1, max_length=32, description="lift | export | retrain | refresh_proposals")
    params: dict[str, Any] = Field(default_factory=dict, description="Kind-specific parameters.")


class JobKindPublic(BaseModel):
    """A job kind a lead may submit: what it does, whether this server runs it, and its params' JSON Schema
    (e.g. the export's formats, pose choices and the fields each needs)."""

    kind: str
    description: str
    available: bool
    reason: str | None = Field(default=None, description="Why this server cannot run it (when unavailable).")
    params_schema: dict[str, Any] | None = Field(default=None, description="JSON Schema of `params`.")


class JobPublic(BaseModel):
    """A job's state and progress; `download_url` is set once a succeeded job has a file to fetch."""

    model_config = ConfigDict(from_attributes=True)
    id: int
    site_id: int
    kind: str
    params: dict[str, Any]
    state: JobState
    progress: float
    message: str
    cancel_requested: bool
    created_by: str
    created_at: datetime
    started_at: datetime | None
    finished_at: datetime | None
    updated_at: datetime
    download_url: str | None
