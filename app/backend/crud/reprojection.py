"""Per-element reprojection figures, cached in `element_reprojection`, and the lead's worst-reprojection queue.

A cached row counts while its element version and inputs digest (`cameras.reprojection.inputs_digest`: poses,
elevation, mask source) are the current ones; otherwise the figures are computed again and the row overwritten.
The queue computes the missing figures of a site lazily, as many as fit in a time budget per request, and says
how many are still pending (the client asks again).
"""

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass

from sqlalchemy import select
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session

from app.backend.cameras.context import CameraContext
from app.backend.cameras.reprojection import (
    MASK_CLASSES,
    NOT_SCORED,
    InstanceCache,
    ReprojectionFigures,
    element_figures,
    inputs_digest,
)
from app.backend.clock import utc_now
from app.backend.models import Element
from app.backend.models_reprojection import ElementReprojection
from app.backend.schemas_reprojection import ReprojectionPublic, ReprojectionQueueItem, ReprojectionQueuePage

logger = logging.getLogger(__name__)

QUEUE_BUDGET_S = 2.0
"""How long one queue request may spend computing missing figures."""


@dataclass(frozen=True)
class _Snapshot:
    """What scoring needs of an element, read once (commits would otherwise reload each element)."""

    id: int
    cls: str
    state: str
    version: int
    points: list[list[float]]

    @classmethod
    def of(cls, element: Element) -> "_Snapshot":
        return cls(element.id, element.cls, element.state, element.version, element.points)


def _public(element_id: int, version: int, row: ElementReprojection) -> ReprojectionPublic:
    """The API shape of a cached row."""
    return ReprojectionPublic(
        element_id=element_id,
        element_version=version,
        sre_px=row.sre_px,
        matched_share=row.matched_share,
        images=row.images,
        computed_at=row.computed_at,
        notice=row.notice,
    )


def _unscored(element_id: int, version: int, notice: str | None) -> ReprojectionPublic:
    """Figures that cannot exist (no reconstruction, a crosswalk): nulls with the reason."""
    return ReprojectionPublic(
        element_id=element_id,
        element_version=version,
        sre_px=None,
        matched_share=None,
        images=0,
        computed_at=None,
        notice=notice,
    )


def _fresh(row: ElementReprojection | None, version: int, digest: str) -> bool:
    """Whether a cached row holds the figures of this element version under these inputs."""
    return row is not None and row.element_version == version and row.inputs_digest == digest


def _compute(context: CameraContext, element: _Snapshot, instances: InstanceCache) -> ReprojectionFigures:
    """The figures of one element (the call the cache saves)."""
    return element_figures(
        context, element.cls, element.points, instances=instances, element_id=str(element.id)
    )


def _row(
    session: Session, element: _Snapshot, digest: str, figures: ReprojectionFigures
) -> ElementReprojection:
    """The element's cache row set to new figures (added to the session, not committed)."""
    row = session.get(ElementReprojection, element.id)
    if row is None:
        row = ElementReprojection(element_id=element.id)
        session.add(row)
    row.element_version = element.version
    row.inputs_digest = digest
    row.sre_px = figures.sre_px
    row.matched_share = figures.matched_share
    row.images = figures.images
    row.notice = figures.notice
    row.computed_at = utc_now()
    return row


def _commit(session: Session) -> None:
    """Commit stored figures; a concurrent request that stored the same element first wins (rolled back)."""
    try:
        session.commit()
    except IntegrityError:
        session.rollback()
        logger.info("reprojection figures stored concurrently; kept the other request's")


def element_reprojection(
    *, session: Session, element: Element, context: CameraContext, instances: InstanceCache
) -> ReprojectionPublic:
    """An element's figures: from the cache when fresh, else computed and stored."""
    snapshot = _Snapshot.of(element)
    if not context.available:
        return _unscored(snapshot.id, snapshot.version, context.notice)
    if snapshot.cls not in MASK_CLASSES:
        return _unscored(snapshot.id, snapshot.version, NOT_SCORED)
    digest = inputs_digest(context)
    row = session.get(ElementReprojection, snapshot.id)
    if row is not None and _fresh(row, snapshot.version, digest):
        return _public(snapshot.id, snapshot.version, row)
    row = _row(session, snapshot, digest, _compute(context, snapshot, instances))
    public = _public(snapshot.id, snapshot.version, row)
    _commit(session)
    return public


def _queue_key(item: ReprojectionQueueItem) -> tuple[int, float, int]:
    """Worst first: seen but matched nowhere, then by SRE (highest first), then id."""
    if item.sre_px is None:
        return (0, 0.0, item.id)
    return (1, -item.sre_px, item.id)


def _scores(
    session: Session,
    site_id: int,
    context: CameraContext,
    instances: InstanceCache,
    deadline: float,
    clock: Callable[[], float],
) -> tuple[list[tuple[_Snapshot, ReprojectionPublic]], int]:
    """The figures of the site's live scored elements, cached or computed (id order) while the deadline allows,
    at least one; and how many are left pending. The new rows are committed."""
    digest = inputs_digest(context)
    query = select(Element).where(
        Element.site_id == site_id, Element.deleted.is_(False), Element.cls.in_(tuple(MASK_CLASSES))
    )
    elements = [_Snapshot.of(element) for element in session.scalars(query.order_by(Element.id))]
    cached = select(ElementReprojection).join(Element).where(Element.site_id == site_id)
    rows = {row.element_id: row for row in session.scalars(cached)}
    scored: list[tuple[_Snapshot, ReprojectionPublic]] = []
    computed = pending = 0
    for element in elements:
        row = rows.get(element.id)
        if row is not None and _fresh(row, element.version, digest):
            scored.append((element, _public(element.id, element.version, row)))
        elif pending == 0 and (computed == 0 or clock() < deadline):
            row = _row(session, element, digest, _compute(context, element, instances))
            scored.append((element, _public(element.id, element.version, row)))
            computed += 1
        else:
            pending += 1
    if computed:
        _commit(session)
        logger.info(
            "site %d: reprojection figures of %d elements computed, %d pending", site_id, computed, pending
        )
    return scored, pending


def reprojection_queue(
    *,
    session: Session,
    site_id: int,
    context: CameraContext,
    instances: InstanceCache,
    limit: int,
    budget_s: float = QUEUE_BUDGET_S,
    clock: Callable[[], float] = time.monotonic,
) -> ReprojectionQueuePage:
    """The site's live dividers and boundaries seen by some image, worst reprojection first; missing figures
    are computed until `budget_s` is spent (at least one per request), the rest counted as `pending`."""
    if not context.available:
        return ReprojectionQueuePage(items=[], total=0, pending=0, unseen=0, notice=context.notice)
    scored, pending = _scores(session, site_id, context, instances, clock() + budget_s, clock)
    ranked = [
        ReprojectionQueueItem.model_validate(
            {"id": element.id, "cls": element.cls, "state": element.state, **figures.model_dump()}
        )
        for element, figures in scored
        if figures.images > 0
    ]
    ranked.sort(key=_queue_key)
    return ReprojectionQueuePage(
        items=ranked[:limit], total=len(ranked), pending=pending, unseen=len(scored) - len(ranked)
    )
