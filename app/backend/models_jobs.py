"""ORM model for background jobs (lift, export, later retrain and proposal refresh): state, progress, result.

It shares `models.Base`, so Alembic's target metadata sees it once this module is imported
(the migration environment imports it).
"""

import logging
from datetime import datetime
from typing import Any

from sqlalchemy import JSON, Boolean, Float, ForeignKey, Index, Integer, String, Text, text
from sqlalchemy.orm import Mapped, mapped_column

from app.backend.models import Base, UtcDateTime

logger = logging.getLogger(__name__)

JOB_STATES = ("queued", "running", "succeeded", "failed", "cancelled")
FINISHED_STATES = frozenset({"succeeded", "failed", "cancelled"})
ACTIVE_RETRAIN = text("kind = 'retrain' AND state IN ('queued', 'running')")
"""Rows of the partial unique index `uq_jobs_one_active_retrain` (migration 0006)."""


class Job(Base):
    """One background job of a site: queued -> running -> succeeded | failed | cancelled. At most one retrain
    per site is queued or running at a time, whichever process submits it (a partial unique index).

    `cancel_requested` is the cooperative cancel flag: the worker reads it between steps and stops there, so a
    cancel works whichever server process runs the job. `result_path` is the downloadable file, once succeeded.
    """

    __tablename__ = "jobs"
    __table_args__ = (
        Index(
            "uq_jobs_one_active_retrain",
            "site_id",
            unique=True,
            sqlite_where=ACTIVE_RETRAIN,
            postgresql_where=ACTIVE_RETRAIN,
        ),
    )

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    site_id: Mapped[int] = mapped_column(ForeignKey("sites.id", ondelete="CASCADE"), index=True)
    kind: Mapped[str] = mapped_column(String(32))
    params: Mapped[dict[str, Any]] = mapped_column(JSON)
    state: Mapped[str] = mapped_column(String(16), index=True)
    progress: Mapped[float] = mapped_column(Float, default=0.0)
    message: Mapped[str] = mapped_column(Text, default="")
    result_path: Mapped[str | None] = mapped_column(Text, nullable=True)
    cancel_requested: Mapped[bool] = mapped_column(Boolean, default=False)
    created_by: Mapped[str] = mapped_column(String(64))
    created_at: Mapped[datetime] = mapped_column(UtcDateTime())
    started_at: Mapped[datetime | None] = mapped_column(UtcDateTime(), nullable=True)
    finished_at: Mapped[datetime | None] = mapped_column(UtcDateTime(), nullable=True)
    updated_at: Mapped[datetime] = mapped_column(UtcDateTime())
