"""Queues: the lead's review queue, and annotators' work items held by renewable, expiring leases."""

import logging
from typing import Annotated, Any

from fastapi import APIRouter, Query, Response, status
from sqlalchemy.orm import Session

from annotations.schema import ElementClass, ReviewState
from app.backend import crud
from app.backend.api.deps import MAX_ID, CurrentUser, IdPath, LeadUser, LintCacheDep, SessionDep
from app.backend.api.routes.elements import parse_bbox
from app.backend.crud import quality, queues
from app.backend.crud.quality import LintCache
from app.backend.schemas_quality import LintFindingPublic
from app.backend.schemas_review import (
    LeasePublic,
    LeaseRequest,
    QueueItem,
    RegionRequest,
    RegionWorkItem,
    ReviewQueuePage,
)

logger = logging.getLogger(__name__)
router = APIRouter(tags=["queues"])
NO_WORK: dict[int | str, dict[str, Any]] = {204: {"description": "No work item is left for you."}}
LEASE_GONE: dict[int | str, dict[str, Any]] = {409: {"description": "The lease was released or expired."}}


@router.get("/sites/{site_id}/queue/review", response_model=ReviewQueuePage)
def review_queue(
    site_id: IdPath,
    session: SessionDep,
    cache: LintCacheDep,
    _user: LeadUser,
    cls: Annotated[ElementClass | None, Query(alias="class")] = None,
    state: ReviewState | None = None,
    author: Annotated[str | None, Query(max_length=64, description="Last editor's username.")] = None,
    bbox: Annotated[str | None, Query(description="xmin,ymin,xmax,ymax in site metres.")] = None,
    flagged: Annotated[bool, Query(description="Only elements with lint findings.")] = False,
    qa: Annotated[
        bool, Query(description="Only pre-accepted elements sampled for QA that await a lead's decision.")
    ] = False,
    limit: Annotated[int, Query(ge=1, le=1000)] = 100,
    offset: Annotated[int, Query(ge=0, le=MAX_ID)] = 0,
) -> ReviewQueuePage:
    """Leads: live elements, lowest confidence first; human-made elements (no confidence) come last.
    Each item carries its lint findings; `flagged=true` keeps only elements that have some, `qa=true` only
    the pre-accepted sample awaiting QA."""
    findings = quality.findings_by_element(quality.lint_site(session=session, site_id=site_id, cache=cache))
    total, elements = queues.review_queue(
        session=session,
        site_id=site_id,
        cls=cls,
        state=state,
        author=author,
        bbox=parse_bbox(bbox),
        only_ids=findings.keys() if flagged else None,
        qa=qa,
        limit=limit,
        offset=offset,
    )
    items = [
        QueueItem(**crud.public(element).model_dump(), lint=findings.get(element.id, []))
        for element in elements
    ]
    return ReviewQueuePage(total=total, limit=limit, offset=offset, items=items)


def _lint_of(
    session: Session, site_id: int, cache: LintCache
) -> tuple[dict[int, list[LintFindingPublic]], list[int]]:
    """The site's lint findings by element, and the elements with errors (handed out first)."""
    findings = quality.findings_by_element(quality.lint_site(session=session, site_id=site_id, cache=cache))
    return findings, [i for i, found in findings.items() if any(f.severity == "error" for f in found)]


@router.post("/sites/{site_id}/queue/next", response_model=LeasePublic, responses=NO_WORK)
def next_work_item(
    site_id: IdPath,
    session: SessionDep,
    cache: LintCacheDep,
    user: CurrentUser,
    request: LeaseRequest | None = None,
) -> LeasePublic | Response:
    """Lease the next work item: your returned elements first, then proposals with lint errors, then the
    other proposals, each by lowest confidence; the lease lists the item's lint findings."""
    lease_s = (request or LeaseRequest()).lease_s
    findings, errors = _lint_of(session, site_id, cache)
    lease = queues.next_work_item(
        session=session, site_id=site_id, username=user.username, lease_s=lease_s, flagged_ids=errors
    )
    if lease is None:
        return Response(status_code=status.HTTP_204_NO_CONTENT)
    return queues.lease_public(session, lease, lint=findings.get(lease.element_id, []))


@router.post("/sites/{site_id}/queue/next-region", response_model=RegionWorkItem, responses=NO_WORK)
def next_region(
    site_id: IdPath,
    session: SessionDep,
    cache: LintCacheDep,
    user: CurrentUser,
    request: RegionRequest | None = None,
) -> RegionWorkItem | Response:
    """Lease a region: the grid cell holding your next work item (same order as `queue/next`) with every free
    proposal centred in it, one lease each; review, renew or release them like single work items."""
    request = request or RegionRequest()
    findings, errors = _lint_of(session, site_id, cache)
    region = queues.next_region(
        session=session,
        site_id=site_id,
        username=user.username,
        lease_s=request.lease_s,
        cell_m=request.cell_m,
        flagged_ids=errors,
    )
    if region is None:
        return Response(status_code=status.HTTP_204_NO_CONTENT)
    bbox, leases = region
    return RegionWorkItem(
        bbox=bbox,
        leases=[
            queues.lease_public(session, lease, lint=findings.get(lease.element_id, [])) for lease in leases
        ],
    )


@router.get("/leases/{lease_id}", response_model=LeasePublic)
def read_lease(lease_id: IdPath, session: SessionDep, user: CurrentUser) -> LeasePublic:
    """One lease (its holder, a lead or an admin): whether it is still active, and its element."""
    lease = queues.read_lease(session=session, lease_id=lease_id, username=user.username, role=user.role)
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
