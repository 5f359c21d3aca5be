"""Auto-retrain: after enough new corrections of a site, a `retrain` job starts by itself (once per batch).

New corrections are the site's live elements in state `accepted` or `fixed` whose last change is later than the
latest retrain job of the site (any outcome); the loop's own pre-accepted elements do not count. No job starts
while a retrain of the site is queued or running: checked first, and guaranteed by the database (a partial
unique index refuses a second active retrain of a site), so it holds across threads and server processes.
"""

import logging
from datetime import datetime

from sqlalchemy import func, select
from sqlalchemy.orm import Session

from app.backend.config import Settings
from app.backend.errors import ConflictError
from app.backend.jobs.runner import JobRunner
from app.backend.jobs.vma import LOOP_USER, RetrainParams
from app.backend.models import Element
from app.backend.models_jobs import Job
from app.backend.vma_loop import should_retrain

logger = logging.getLogger(__name__)

CORRECTION_STATES = ("accepted", "fixed")
AUTO_USER = "auto-retrain"
"""`created_by` of jobs the loop starts itself."""


def new_corrections(session: Session, site_id: int, since: datetime | None) -> int:
    """Accepted/fixed elements of the site changed after `since` (all of them when None)."""
    query = select(func.count()).where(
        Element.site_id == site_id,
        Element.deleted.is_(False),
        Element.state.in_(CORRECTION_STATES),
        Element.author != LOOP_USER,
    )
    if since is not None:
        query = query.where(Element.updated_at > since)
    return int(session.scalar(query) or 0)


def maybe_retrain(*, session: Session, runner: JobRunner, settings: Settings, site_id: int) -> Job | None:
    """Start a retrain job of the site when enough corrections arrived since the last one; the job or None."""
    if settings.retrain_after <= 0 or "retrain" not in runner.kinds:
        return None
    last = session.execute(
        select(Job.state, Job.created_at)
        .where(Job.site_id == site_id, Job.kind == "retrain")
        .order_by(Job.id.desc())
        .limit(1)
    ).first()
    if last is not None and last.state in ("queued", "running"):
        return None
    count = new_corrections(session, site_id, None if last is None else last.created_at)
    if not should_retrain(count, settings.retrain_after):
        return None
    params = RetrainParams().model_dump(mode="json")
    try:
        job = runner.enqueue(session, site_id=site_id, kind="retrain", params=params, username=AUTO_USER)
    except ConflictError:
        logger.info("site %d: a retrain was started meanwhile by another request or process", site_id)
        return None
    logger.info("site %d: %d new corrections, retrain job %d started", site_id, count, job.id)
    return job
