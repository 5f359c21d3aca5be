"""ORM models for queues and review issues: work-item leases, issues pinned to a point or element, their threads.

These share `models.Base`, so Alembic's target metadata sees them once this module is imported
(the migration environment imports it).
"""

import logging
from datetime import datetime

from sqlalchemy import Float, ForeignKey, Integer, String, Text
from sqlalchemy.orm import Mapped, mapped_column, relationship

from app.backend.models import Base, UtcDateTime

logger = logging.getLogger(__name__)


class Lease(Base):
    """One annotator's claim on one element for a limited time; rows are kept after release (history).

    `active_element_id` equals `element_id` while the lease holds the element and is NULL once the lease is
    released or reclaimed after expiry. Its UNIQUE constraint is the database-level guard that at most one
    lease holds an element, whatever the number of concurrent requests or server processes.
    """

    __tablename__ = "leases"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    site_id: Mapped[int] = mapped_column(ForeignKey("sites.id", ondelete="CASCADE"), index=True)
    element_id: Mapped[int] = mapped_column(ForeignKey("elements.id", ondelete="CASCADE"), index=True)
    active_element_id: Mapped[int | None] = mapped_column(Integer, nullable=True, unique=True)
    username: Mapped[str] = mapped_column(String(64), index=True)
    acquired_at: Mapped[datetime] = mapped_column(UtcDateTime())
    expires_at: Mapped[datetime] = mapped_column(UtcDateTime())
    released_at: Mapped[datetime | None] = mapped_column(UtcDateTime(), nullable=True)


class ReviewIssue(Base):
    """A lead's remark pinned to a point in site metres and/or an element; open until resolved."""

    __tablename__ = "review_issues"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    site_id: Mapped[int] = mapped_column(ForeignKey("sites.id", ondelete="CASCADE"), index=True)
    element_id: Mapped[int | None] = mapped_column(
        ForeignKey("elements.id", ondelete="SET NULL"), nullable=True, index=True
    )
    x: Mapped[float | None] = mapped_column(Float, nullable=True)
    y: Mapped[float | None] = mapped_column(Float, nullable=True)
    reason: Mapped[str] = mapped_column(String(32))
    status: Mapped[str] = mapped_column(String(16), index=True)
    created_by: Mapped[str] = mapped_column(String(64))
    created_at: Mapped[datetime] = mapped_column(UtcDateTime())
    updated_at: Mapped[datetime] = mapped_column(UtcDateTime())
    comments: Mapped[list["IssueComment"]] = relationship(
        order_by="IssueComment.id", lazy="selectin", cascade="all, delete-orphan"
    )


class IssueComment(Base):
    """One append-only entry of an issue's thread: a comment, or the record of opening, resolving, reopening."""

    __tablename__ = "issue_comments"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    issue_id: Mapped[int] = mapped_column(ForeignKey("review_issues.id", ondelete="CASCADE"), index=True)
    kind: Mapped[str] = mapped_column(String(16))
    username: Mapped[str] = mapped_column(String(64))
    at: Mapped[datetime] = mapped_column(UtcDateTime())
    body: Mapped[str] = mapped_column(Text)
