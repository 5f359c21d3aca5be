"""Queues: the lead's review queue, and annotators' work items held by renewable, expiring leases."""

import logging
from typing import Annotated, Any

from fastapi import APIRouter, Query, Response, status

from annotations.schema import ElementClass, ReviewState
from app.backend import crud
from app.backend.api.deps import MAX_ID, CurrentUser, IdPath, LeadUser, SessionDep
from app.backend.api.routes.elements import parse_bbox
from app.backend.crud import queues
from app.backend.schemas_review import LeasePublic, LeaseRequest, ReviewQueuePage

logger = logging.getLogger(__name__)
router = APIRouter(tags=["queues"])
NO_WORK: dict[int | str, dict[str, Any]] = {204: {"description": "No work item is left for you."}}
LEASE_GONE: dict[int | str, dict[str, Any]] = {409: {"description": "The lease was released or expired."}}


@router.get("/sites/{site_id}/queue/review", response_model=ReviewQueuePage)
def review_queue(
    site_id: IdPath,
    session: SessionDep,
    _user: LeadUser,
    cls: Annotated[ElementClass | None, Query(alias="class")] = None,
    state: ReviewState | None = None,
    author: Annotated[str | None, Query(max_length=64, description="Last editor's username.")] = None,
    bbox: Annotated[str | None, Query(description="xmin,ymin,xmax,ymax in site metres.")] = None,
    limit: Annotated[int, Query(ge=1, le=1000)] = 100,
    offset: Annotated[int, Query(ge=0, le=MAX_ID)] = 0,
) -> ReviewQueuePage:
    """Leads: live elements, lowest confidence first; human-made elements (no confidence) come last."""
    total, elements = queues.review_queue(
        session=session,
        site_id=site_id,
        cls=cls,
        state=state,
        author=author,
        bbox=parse_bbox(bbox),
        limit=limit,
        offset=offset,
    )
    items = [crud.public(element) for element in elements]
    return ReviewQueuePage(total=total, limit=limit, offset=offset, items=items)


@router.post("/sites/{site_id}/queue/next", response_model=LeasePublic, responses=NO_WORK)
def next_work_item(
    site_id: IdPath, session: SessionDep, user: CurrentUser, request: LeaseRequest | None = None
) -> LeasePublic | Response:
    """Lease the next work item: your returned elements first, then proposals by lowest confidence."""
    lease_s = (request or LeaseRequest()).lease_s
    lease = queues.next_work_item(session=session, site_id=site_id, username=user.username, lease_s=lease_s)
    if lease is None:
        return Response(status_code=status.HTTP_204_NO_CONTENT)
    return queues.lease_public(session, lease)


@router.post("/leases/{lease_id}/release", response_model=LeasePublic)
def release_lease(lease_id: IdPath, session: SessionDep, user: CurrentUser) -> LeasePublic:
    """Give the item back (its holder, a lead or an admin); it is free for the next request."""
    lease = queues.release_lease(session=session, lease_id=lease_id, username=user.username, role=user.role)
    return queues.lease_public(session, lease)


@router.post("/leases/{lease_id}/renew", response_model=LeasePublic, responses=LEASE_GONE)
def renew_lease(
    lease_id: IdPath, session: SessionDep, user: CurrentUser, request: LeaseRequest | None = None
) -> LeasePublic:
    """Extend your unexpired lease to `lease_s` seconds from now (default 10 minutes)."""
    lease_s = (request or LeaseRequest()).lease_s
    lease = queues.renew_lease(session=session, lease_id=lease_id, username=user.username, lease_s=lease_s)
    return queues.lease_public(session, lease)
