"""Review issues: leads pin them to a point or element; everyone reads and replies; leads resolve and reopen."""

import logging
from typing import Annotated, Any

from fastapi import APIRouter, Query, status

from app.backend.api.deps import MAX_ID, CurrentUser, IdPath, LeadUser, SessionDep, SettingsDep
from app.backend.crud import issues
from app.backend.schemas_review import (
    CommentCreate,
    IssueAction,
    IssueCreate,
    IssuePublic,
    IssueReason,
    IssueStatus,
)

logger = logging.getLogger(__name__)
router = APIRouter(tags=["issues"])
CONFLICT: dict[int | str, dict[str, Any]] = {409: {"description": "The issue already has that status."}}


@router.post("/sites/{site_id}/issues", response_model=IssuePublic, status_code=status.HTTP_201_CREATED)
def create_issue(
    site_id: IdPath, issue_in: IssueCreate, session: SessionDep, settings: SettingsDep, user: LeadUser
) -> IssuePublic:
    """Leads: pin an open issue to a point (site metres) and/or an element; the comment opens its thread."""
    issue = issues.create_issue(
        session=session,
        site_id=site_id,
        issue_in=issue_in,
        username=user.username,
        margin_m=settings.extent_margin_m,
    )
    return issues.issue_public(issue)


@router.get("/sites/{site_id}/issues", response_model=list[IssuePublic])
def list_issues(
    site_id: IdPath,
    session: SessionDep,
    _user: CurrentUser,
    issue_status: Annotated[IssueStatus | None, Query(alias="status")] = None,
    element_id: Annotated[int | None, Query(ge=1, le=MAX_ID)] = None,
    reason: IssueReason | None = None,
    limit: Annotated[int, Query(ge=1, le=1000)] = 100,
    offset: Annotated[int, Query(ge=0, le=MAX_ID)] = 0,
) -> list[IssuePublic]:
    """Issues of a site, oldest first, filtered by status, element and reason."""
    found = issues.list_issues(
        session=session,
        site_id=site_id,
        status=issue_status,
        element_id=element_id,
        reason=reason,
        limit=limit,
        offset=offset,
    )
    return [issues.issue_public(issue) for issue in found]


@router.get("/issues/{issue_id}", response_model=IssuePublic)
def read_issue(issue_id: IdPath, session: SessionDep, _user: CurrentUser) -> IssuePublic:
    """One issue with its thread."""
    return issues.issue_public(issues.get_issue(session=session, issue_id=issue_id))


@router.post("/issues/{issue_id}/comments", response_model=IssuePublic, status_code=status.HTTP_201_CREATED)
def add_comment(
    issue_id: IdPath, comment: CommentCreate, session: SessionDep, user: CurrentUser
) -> IssuePublic:
    """Reply in the thread; annotators may reply too (to explain a fix or ask), but not pin or resolve."""
    issue = issues.add_comment(session=session, issue_id=issue_id, username=user.username, body=comment.body)
    return issues.issue_public(issue)


@router.post("/issues/{issue_id}/resolve", response_model=IssuePublic, responses=CONFLICT)
def resolve_issue(
    issue_id: IdPath, session: SessionDep, user: LeadUser, action: IssueAction | None = None
) -> IssuePublic:
    """Leads: mark an open issue resolved, with an optional note."""
    comment = None if action is None else action.comment
    issue = issues.set_status(
        session=session, issue_id=issue_id, target="resolved", username=user.username, comment=comment
    )
    return issues.issue_public(issue)


@router.post("/issues/{issue_id}/reopen", response_model=IssuePublic, responses=CONFLICT)
def reopen_issue(
    issue_id: IdPath, session: SessionDep, user: LeadUser, action: IssueAction | None = None
) -> IssuePublic:
    """Leads: reopen a resolved issue, with an optional note."""
    comment = None if action is None else action.comment
    issue = issues.set_status(
        session=session, issue_id=issue_id, target="open", username=user.username, comment=comment
    )
    return issues.issue_public(issue)
