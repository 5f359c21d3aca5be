"""API shapes for queues (review queue pages, work-item leases) and review issues with their threads."""

import logging
from datetime import datetime
from typing import Literal, Self

from pydantic import BaseModel, ConfigDict, Field, model_validator

from app.backend.schemas import STRICT, DbId, ElementPublic, Point
from app.backend.schemas_quality import LintFindingPublic

logger = logging.getLogger(__name__)

DEFAULT_LEASE_S = 600
"""How long a work item stays leased to an annotator unless renewed or released (10 minutes)."""
MAX_LEASE_S = 4 * 3600

IssueReason = Literal[
    "wrong_class", "wrong_geometry", "wrong_direction", "missing_element", "extra_element", "other"
]
IssueStatus = Literal["open", "resolved"]


class QueueItem(ElementPublic):
    """An element in a queue, with the lint findings that involve it (empty when it is clean)."""

    lint: list[LintFindingPublic] = Field(default_factory=list)


class ReviewQueuePage(BaseModel):
    """One page of a lead's review queue: lowest confidence first, human-made (no confidence) last."""

    total: int
    limit: int
    offset: int
    items: list[QueueItem]


class LeaseRequest(BaseModel):
    """Optional lease length for `queue/next` and `renew`."""

    model_config = STRICT
    lease_s: int = Field(default=DEFAULT_LEASE_S, ge=1, le=MAX_LEASE_S, description="Lease length, seconds.")


class LeasePublic(BaseModel):
    """A lease on one element; `active` is false once released or expired."""

    id: int
    site_id: int
    element_id: int
    username: str
    acquired_at: datetime
    expires_at: datetime
    released_at: datetime | None
    active: bool
    element: ElementPublic
    lint: list[LintFindingPublic] = Field(
        default_factory=list, description="Lint findings involving the element: what to look at first."
    )


class RegionRequest(LeaseRequest):
    """Optional lease length and grid cell size for `queue/next-region`."""

    cell_m: float = Field(
        default=50.0, ge=5.0, le=1000.0, description="Side of the region grid cells, metres."
    )


class RegionWorkItem(BaseModel):
    """A region work item: a grid cell of the site and one lease per proposal in it (release or renew each)."""

    bbox: tuple[float, float, float, float] = Field(description="xmin, ymin, xmax, ymax in site metres.")
    leases: list[LeasePublic]


class IssueCreate(BaseModel):
    """Pin an issue to a point (site metres), to an element, or both; the comment opens the thread."""

    model_config = STRICT
    reason: IssueReason
    comment: str = Field(min_length=1, max_length=10_000)
    point: Point | None = None
    element_id: DbId | None = None

    @model_validator(mode="after")
    def _pinned(self) -> Self:
        """An issue must be pinned somewhere."""
        if self.point is None and self.element_id is None:
            raise ValueError("give point, element_id, or both")
        return self


class CommentCreate(BaseModel):
    """A reply in an issue's thread."""

    model_config = STRICT
    body: str = Field(min_length=1, max_length=10_000)


class IssueAction(BaseModel):
    """Resolve or reopen, with an optional note for the thread."""

    model_config = STRICT
    comment: str | None = Field(default=None, max_length=10_000)


class CommentPublic(BaseModel):
    """One thread entry: `kind` is comment, open, resolve or reopen."""

    model_config = ConfigDict(from_attributes=True)
    id: int
    kind: Literal["comment", "open", "resolve", "reopen"]
    username: str
    at: datetime
    body: str


class IssuePublic(BaseModel):
    """An issue with its whole thread, oldest entry first."""

    id: int
    site_id: int
    element_id: int | None
    point: Point | None
    reason: IssueReason
    status: IssueStatus
    created_by: str
    created_at: datetime
    updated_at: datetime
    comments: list[CommentPublic]
