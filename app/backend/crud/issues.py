"""Review issues: pinned by leads to a point or an element, with an append-only thread; resolve and reopen.

Every change to an issue appends a thread entry (`open`, `comment`, `resolve`, `reopen`) naming who and when,
so the thread is the issue's log.
"""

import logging

from sqlalchemy import select
from sqlalchemy.orm import Session

from app.backend.clock import as_utc, utc_now
from app.backend.crud.elements import check_in_site, get_element
from app.backend.crud.sites import get_site
from app.backend.errors import ConflictError, NotFoundError
from app.backend.models_review import IssueComment, ReviewIssue
from app.backend.schemas_review import CommentPublic, IssueCreate, IssuePublic

logger = logging.getLogger(__name__)


def issue_public(issue: ReviewIssue) -> IssuePublic:
    """The API view of an issue and its thread."""
    point = None if issue.x is None or issue.y is None else (issue.x, issue.y)
    return IssuePublic(
        id=issue.id,
        site_id=issue.site_id,
        element_id=issue.element_id,
        point=point,
        reason=issue.reason,  # type: ignore[arg-type]
        status=issue.status,  # type: ignore[arg-type]
        created_by=issue.created_by,
        created_at=as_utc(issue.created_at),
        updated_at=as_utc(issue.updated_at),
        comments=[
            CommentPublic(id=c.id, kind=c.kind, username=c.username, at=as_utc(c.at), body=c.body)  # type: ignore[arg-type]
            for c in issue.comments
        ],
    )


def create_issue(
    *, session: Session, site_id: int, issue_in: IssueCreate, username: str, margin_m: float
) -> ReviewIssue:
    """Pin a new open issue; 404 for an element not in the site, 422 for a point far outside it."""
    site = get_site(session=session, site_id=site_id)
    if issue_in.element_id is not None:
        get_element(session=session, site_id=site_id, element_id=issue_in.element_id)
    if issue_in.point is not None:
        check_in_site(site=site, points=[issue_in.point], margin_m=margin_m)
    now = utc_now()
    issue = ReviewIssue(
        site_id=site_id,
        element_id=issue_in.element_id,
        x=None if issue_in.point is None else issue_in.point[0],
        y=None if issue_in.point is None else issue_in.point[1],
        reason=issue_in.reason,
        status="open",
        created_by=username,
        created_at=now,
        updated_at=now,
    )
    issue.comments.append(IssueComment(kind="open", username=username, at=now, body=issue_in.comment))
    session.add(issue)
    session.commit()
    logger.info("issue %s pinned in site %s by %s", issue.id, site_id, username)
    return issue


def list_issues(
    *,
    session: Session,
    site_id: int,
    status: str | None = None,
    element_id: int | None = None,
    reason: str | None = None,
    limit: int = 100,
    offset: int = 0,
) -> list[ReviewIssue]:
    """Issues of a site, oldest first, filtered by status, element and reason."""
    get_site(session=session, site_id=site_id)
    query = select(ReviewIssue).where(ReviewIssue.site_id == site_id)
    if status is not None:
        query = query.where(ReviewIssue.status == status)
    if element_id is not None:
        query = query.where(ReviewIssue.element_id == element_id)
    if reason is not None:
        query = query.where(ReviewIssue.reason == reason)
    return list(session.scalars(query.order_by(ReviewIssue.id).limit(limit).offset(offset)))


def get_issue(*, session: Session, issue_id: int) -> ReviewIssue:
    """The issue with this id; NotFoundError otherwise."""
    issue = session.get(ReviewIssue, issue_id)
    if issue is None:
        raise NotFoundError(f"issue {issue_id} not found")
    return issue


def _append(session: Session, issue: ReviewIssue, *, kind: str, username: str, body: str) -> ReviewIssue:
    """Append one thread entry, touch the issue and commit."""
    now = utc_now()
    issue.comments.append(IssueComment(kind=kind, username=username, at=now, body=body))
    issue.updated_at = now
    session.commit()
    return issue


def add_comment(*, session: Session, issue_id: int, username: str, body: str) -> ReviewIssue:
    """Reply in the thread (open or resolved issues alike)."""
    issue = get_issue(session=session, issue_id=issue_id)
    return _append(session, issue, kind="comment", username=username, body=body)


def set_status(
    *, session: Session, issue_id: int, target: str, username: str, comment: str | None
) -> ReviewIssue:
    """Resolve an open issue or reopen a resolved one; 409 when it already has that status."""
    issue = get_issue(session=session, issue_id=issue_id)
    if issue.status == target:
        raise ConflictError(f"status: issue {issue_id} is already {target}")
    issue.status = target
    kind = "resolve" if target == "resolved" else "reopen"
    logger.info("issue %s %s by %s", issue_id, target, username)
    return _append(session, issue, kind=kind, username=username, body=comment or "")
