"""ORM models (SQLAlchemy 2): users, tokens, sites, map elements and the append-only edit log.

These are storage classes only; the API's request and response shapes live in `schemas.py`.
"""

import logging
from datetime import UTC, datetime
from typing import Any

from sqlalchemy import JSON, Boolean, DateTime, Dialect, Float, ForeignKey, Index, Integer, String, Text
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column
from sqlalchemy.types import TypeDecorator

logger = logging.getLogger(__name__)


class UtcDateTime(TypeDecorator[datetime]):
    """A timestamp stored in UTC and always read back timezone-aware (SQLite drops the offset otherwise)."""

    impl = DateTime(timezone=True)
    cache_ok = True

    def process_bind_param(self, value: datetime | None, dialect: Dialect) -> datetime | None:
        if value is None:
            return None
        return value.replace(tzinfo=UTC) if value.tzinfo is None else value.astimezone(UTC)

    def process_result_value(self, value: datetime | None, dialect: Dialect) -> datetime | None:
        if value is None:
            return None
        return value.replace(tzinfo=UTC) if value.tzinfo is None else value.astimezone(UTC)


class Base(DeclarativeBase):
    """Declarative base shared by every table (Alembic's target metadata)."""


class User(Base):
    """A person who logs in: annotator, lead or admin."""

    __tablename__ = "users"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    username: Mapped[str] = mapped_column(String(64), unique=True, index=True)
    role: Mapped[str] = mapped_column(String(16))
    password_hash: Mapped[str] = mapped_column(String(255))
    is_active: Mapped[bool] = mapped_column(Boolean, default=True)
    created_at: Mapped[datetime] = mapped_column(UtcDateTime())


class Token(Base):
    """A login token; only its SHA-256 digest is stored, so a leaked database leaks no usable token."""

    __tablename__ = "tokens"

    token_hash: Mapped[str] = mapped_column(String(64), primary_key=True)
    user_id: Mapped[int] = mapped_column(ForeignKey("users.id", ondelete="CASCADE"), index=True)
    expires_at: Mapped[datetime] = mapped_column(UtcDateTime())


class Site(Base):
    """An annotated area: its origin, raster georeference, where its BEV rasters lie and, when known, the data set
    and reconstruction its camera images and poses come from."""

    __tablename__ = "sites"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    name: Mapped[str] = mapped_column(String(128), unique=True)
    site_origin_x: Mapped[float] = mapped_column(Float)
    site_origin_y: Mapped[float] = mapped_column(Float)
    georeference: Mapped[dict[str, Any]] = mapped_column(JSON)
    raster_dir: Mapped[str] = mapped_column(Text)
    created_at: Mapped[datetime] = mapped_column(UtcDateTime())
    dataset_root: Mapped[str | None] = mapped_column(Text, nullable=True)
    """The nuScenes-layout data set of the site's camera images (resolved, inside the data roots), if known."""
    workspace_dir: Mapped[str | None] = mapped_column(Text, nullable=True)
    """The pipeline workspace of the site's reconstruction (resolved, inside the data roots), if known."""
    recon_site_id: Mapped[str | None] = mapped_column(String(128), nullable=True)
    """The reconstruction's site id in `workspace_dir` (its SfM poses give the camera panel's poses)."""


class Element(Base):
    """The current version of one map element; every change is mirrored by an `EditLog` row."""

    __tablename__ = "elements"
    __table_args__ = (
        Index("ix_elements_site_bbox", "site_id", "bbox_xmin", "bbox_xmax", "bbox_ymin", "bbox_ymax"),
    )

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    site_id: Mapped[int] = mapped_column(ForeignKey("sites.id", ondelete="CASCADE"), index=True)
    cls: Mapped[str] = mapped_column("class", String(32))
    points: Mapped[list[list[float]]] = mapped_column(JSON)
    xmin: Mapped[float] = mapped_column("bbox_xmin", Float)
    ymin: Mapped[float] = mapped_column("bbox_ymin", Float)
    xmax: Mapped[float] = mapped_column("bbox_xmax", Float)
    ymax: Mapped[float] = mapped_column("bbox_ymax", Float)
    confidence: Mapped[float | None] = mapped_column(Float, nullable=True)
    source: Mapped[str] = mapped_column(String(16))
    state: Mapped[str] = mapped_column(String(16), index=True)
    deleted: Mapped[bool] = mapped_column(Boolean, default=False)
    version: Mapped[int] = mapped_column(Integer, nullable=False)
    author: Mapped[str | None] = mapped_column(String(64), nullable=True)
    created_at: Mapped[datetime] = mapped_column(UtcDateTime())
    updated_at: Mapped[datetime] = mapped_column(UtcDateTime())
    proposal: Mapped[dict[str, Any] | None] = mapped_column(JSON, nullable=True)
    """Snapshot of the element as first proposed (class, points, confidence), for proposal-to-final diffs."""
    preaccepted: Mapped[bool] = mapped_column(Boolean, default=False)
    """Entered as `accepted` because the model's confidence passed the calibrated threshold (no person yet)."""
    qa_sample: Mapped[bool] = mapped_column(Boolean, default=False)
    """A pre-accepted element sampled for the lead's QA queue."""

    __mapper_args__ = {"version_id_col": version}  # the ORM's optimistic lock: UPDATE ... WHERE version = old


class EditLog(Base):
    """Append-only record of one change to an element: who, when, what, and the state before and after."""

    __tablename__ = "edit_log"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    element_id: Mapped[int] = mapped_column(ForeignKey("elements.id", ondelete="CASCADE"), index=True)
    version: Mapped[int] = mapped_column(Integer)
    username: Mapped[str] = mapped_column(String(64))
    at: Mapped[datetime] = mapped_column(UtcDateTime())
    action: Mapped[str] = mapped_column(String(16))
    before: Mapped[dict[str, Any] | None] = mapped_column(JSON, nullable=True)
    after: Mapped[dict[str, Any]] = mapped_column(JSON)
