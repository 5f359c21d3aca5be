"""Map elements with versions: create, bulk proposals, bbox query, update, soft delete.

Every change bumps the version (the ORM's optimistic lock) and appends an `EditLog` row in the same
transaction, so nothing is changed without a record of who, when, before and after. Every change of an existing
element (update, delete, review, restore) loads it through `element_for_write`, the one place for the rules all
of them share: approved work, leases held by others, and the version.
"""

import logging
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from sqlalchemy import select
from sqlalchemy.orm import Session
from sqlalchemy.orm.exc import StaleDataError

from app.backend.clock import utc_now
from app.backend.crud.leases import check_lease
from app.backend.crud.limits import VertexLimits, check_vertex_limits
from app.backend.crud.sites import cached_extent, get_site, site_extent
from app.backend.errors import ConflictError, ForbiddenError, InvalidInputError, NotFoundError
from app.backend.models import EditLog, Element, Site
from app.backend.schemas import ElementCreate, ElementPublic, ElementUpdate, Extent, Point, check_element
from app.backend.vma_loop import qa_sample

logger = logging.getLogger(__name__)

FINAL_STATES = frozenset({"approved"})
"""A lead's final decision: only a lead (or admin) may edit or delete an element in these states; an annotator's
edit is refused (403), not taken as a reopening: a lead returns the element first."""


def public(element: Element) -> ElementPublic:
    """The API view of an element."""
    return ElementPublic(
        id=element.id,
        site_id=element.site_id,
        cls=element.cls,  # type: ignore[arg-type]
        points=[(p[0], p[1]) for p in element.points],
        confidence=element.confidence,
        source=element.source,  # type: ignore[arg-type]
        state=element.state,  # type: ignore[arg-type]
        deleted=element.deleted,
        version=element.version,
        author=element.author,
        created_at=element.created_at,
        updated_at=element.updated_at,
        proposed_by=(element.proposal or {}).get("model"),
        preaccepted=element.preaccepted,
        qa_sample=element.qa_sample,
    )


def snapshot(element: Element) -> dict[str, Any]:
    """The editable content of an element as JSON, for the edit log."""
    return {
        "class": element.cls,
        "points": [list(p) for p in element.points],
        "confidence": element.confidence,
        "source": element.source,
        "state": element.state,
        "deleted": element.deleted,
    }


def check_in_site(*, site: Site, points: Sequence[Point], margin_m: float) -> None:
    """InvalidInputError when a vertex lies more than `margin_m` outside the site's raster extent."""
    check_in_extent(box=site_extent(site), points=points, margin_m=margin_m)


def check_in_extent(*, box: Extent, points: Sequence[Point], margin_m: float) -> None:
    """InvalidInputError when a vertex lies more than `margin_m` outside `box`."""
    for index, (x, y) in enumerate(points):
        if not (
            box.xmin - margin_m <= x <= box.xmax + margin_m
            and box.ymin - margin_m <= y <= box.ymax + margin_m
        ):
            raise InvalidInputError(
                "points",
                f"point {index} ({x:.2f}, {y:.2f}) is more than {margin_m} m outside the site extent "
                f"x [{box.xmin:.2f}, {box.xmax:.2f}], y [{box.ymin:.2f}, {box.ymax:.2f}]",
            )


def _set_points(element: Element, points: Sequence[Point]) -> None:
    """Store the points and their bounding box (indexed for bbox queries)."""
    element.points = [[float(x), float(y)] for x, y in points]
    element.xmin = min(p[0] for p in element.points)
    element.xmax = max(p[0] for p in element.points)
    element.ymin = min(p[1] for p in element.points)
    element.ymax = max(p[1] for p in element.points)


def log_change(
    session: Session,
    element: Element,
    *,
    username: str,
    action: str,
    before: dict[str, Any] | None,
    version: int | None = None,
) -> None:
    """Append the log row for the element's `version` (default: its current one, so call after the flush that
    set it)."""
    session.add(
        EditLog(
            element_id=element.id,
            version=element.version if version is None else version,
            username=username,
            at=element.updated_at,
            action=action,
            before=before,
            after=snapshot(element),
        )
    )


def new_element(site: Site, element_in: ElementCreate, *, username: str) -> Element:
    """An unsaved element from validated input; proposals keep a snapshot for proposal-to-final diffs."""
    now = utc_now()
    element = Element(
        site_id=site.id,
        cls=element_in.cls,
        confidence=element_in.confidence,
        source=element_in.source,
        state="proposed",
        deleted=False,
        preaccepted=False,
        qa_sample=False,
        author=username,
        created_at=now,
        updated_at=now,
    )
    _set_points(element, element_in.points)
    if element_in.source == "proposal":
        element.proposal = {
            "class": element.cls,
            "points": element.points,
            "confidence": element.confidence,
            "model": element_in.model,
        }
    return element


@dataclass(frozen=True)
class Preaccept:
    """How confident proposals enter: at or above `threshold` as pre-accepted `accepted`, and a reproducible
    share of those (`qa_share`, drawn with `seed`) flagged for the lead's QA queue."""

    threshold: float
    qa_share: float
    seed: int


def mark_preaccepted(elements: Sequence[Element], preaccept: Preaccept) -> None:
    """Set state and flags of unsaved proposals by their confidence (call before they are first flushed, so
    that they enter at version 1)."""
    confident = [
        k
        for k, e in enumerate(elements)
        if e.source == "proposal" and e.confidence is not None and e.confidence >= preaccept.threshold
    ]
    sampled = qa_sample(confident, preaccept.qa_share, preaccept.seed)
    for k in confident:
        elements[k].state, elements[k].preaccepted, elements[k].qa_sample = "accepted", True, k in sampled


def create_elements(
    *,
    session: Session,
    site_id: int,
    elements_in: Sequence[ElementCreate],
    username: str,
    margin_m: float,
    preaccept: Preaccept | None = None,
    limits: VertexLimits | None = None,
) -> list[Element]:
    """Store new elements (all or none), each with a `create` log entry; confident proposals pre-accepted
    when `preaccept` is given; 422 past the vertex `limits` when given."""
    site = get_site(session=session, site_id=site_id)
    if limits is not None:
        fields = (
            ["points"] if len(elements_in) == 1 else [f"elements.{k}.points" for k in range(len(elements_in))]
        )
        counts = [len(element_in.points) for element_in in elements_in]
        check_vertex_limits(session=session, site_id=site_id, limits=limits, counts=counts, fields=fields)
    for index, element_in in enumerate(elements_in):
        try:
            check_in_site(site=site, points=element_in.points, margin_m=margin_m)
        except InvalidInputError as error:
            field = "points" if len(elements_in) == 1 else f"elements.{index}.points"
            raise InvalidInputError(field, error.message) from None
    elements = [new_element(site, element_in, username=username) for element_in in elements_in]
    if preaccept is not None:
        mark_preaccepted(elements, preaccept)
    session.add_all(elements)
    session.flush()
    for element in elements:
        log_change(session, element, username=username, action="create", before=None)
    session.commit()
    return elements


def get_element(*, session: Session, site_id: int, element_id: int) -> Element:
    """The element of this site with this id (deleted ones too); NotFoundError otherwise."""
    element = session.get(Element, element_id)
    if element is None or element.site_id != site_id:
        raise NotFoundError(f"element {element_id} not found in site {site_id}")
    return element


def query_elements(
    *,
    session: Session,
    site_id: int,
    bbox: tuple[float, float, float, float] | None = None,
    cls: str | None = None,
    state: str | None = None,
    include_deleted: bool = False,
    limit: int = 10_000,
) -> list[Element]:
    """Elements of a site whose bounding box meets `bbox` (xmin, ymin, xmax, ymax in site metres)."""
    get_site(session=session, site_id=site_id)
    query = select(Element).where(Element.site_id == site_id)
    if bbox is not None:
        xmin, ymin, xmax, ymax = bbox
        query = query.where(
            Element.xmax >= xmin, Element.xmin <= xmax, Element.ymax >= ymin, Element.ymin <= ymax
        )
    if cls is not None:
        query = query.where(Element.cls == cls)
    if state is not None:
        query = query.where(Element.state == state)
    if not include_deleted:
        query = query.where(Element.deleted.is_(False))
    return list(session.scalars(query.order_by(Element.id).limit(limit)))


def check_version(element: Element, version: int) -> None:
    """ConflictError carrying the current element when `version` is not the stored one."""
    if element.version != version:
        raise ConflictError(
            f"version: element {element.id} is at version {element.version}, the request carries {version}; "
            "reload it and apply the change again",
            current=public(element).model_dump(mode="json", by_alias=True),
        )


def element_for_write(
    *, session: Session, site_id: int, element_id: int, version: int, username: str, role: str, action: str
) -> Element:
    """The element `action` (update, delete, review or restore) may change, checked in this order: it exists in
    the site (404); an annotator may not update or delete approved work (403; review and restore apply their
    own state rules); no other user's unexpired lease holds it (409 naming the holder and expiry; leads and
    admins override); `version` is the stored one (409 with the current element)."""
    element = get_element(session=session, site_id=site_id, element_id=element_id)
    if action in ("update", "delete") and element.state in FINAL_STATES and role not in ("lead", "admin"):
        raise ForbiddenError(
            f"state: element {element_id} is {element.state}; only a lead may {action} approved work "
            "(a lead may return it to annotators)"
        )
    check_lease(session, element, username=username, role=role, action=action)
    check_version(element, version)
    return element


def commit_change(
    session: Session, element: Element, *, username: str, action: str, before: dict[str, Any]
) -> Element:
    """Commit the changed element (version bump, UPDATE ... WHERE version = old) with its log row in one flush;
    409 on a lost race. The ORM's version counter adds 1, so the log row's version is known beforehand."""
    element.updated_at = utc_now()
    element.author = username
    log_change(session, element, username=username, action=action, before=before, version=element.version + 1)
    try:
        session.commit()
    except StaleDataError:
        session.rollback()
        current = session.get(Element, element.id)
        raise ConflictError(
            f"version: element {element.id} was changed by someone else; reload it",
            current=None if current is None else public(current).model_dump(mode="json", by_alias=True),
        ) from None
    return element


def update_element(
    *,
    session: Session,
    site_id: int,
    element_id: int,
    update: ElementUpdate,
    username: str,
    role: str,
    margin_m: float,
    limits: VertexLimits | None = None,
) -> Element:
    """Change class, points and/or confidence of the current version; the merged element is validated (422 past
    the vertex `limits` when given). The review state is kept (see `element_for_write` for who may change
    what)."""
    element = element_for_write(
        session=session,
        site_id=site_id,
        element_id=element_id,
        version=update.version,
        username=username,
        role=role,
        action="update",
    )
    if element.deleted:
        raise ConflictError(f"element {element_id} is deleted; restore a version first")
    cls = update.cls or element.cls
    if limits is not None and update.points is not None:
        check_vertex_limits(
            session=session,
            site_id=site_id,
            limits=limits,
            counts=[len(update.points)],
            fields=["points"],
            replaced=len(element.points),
        )
    points = update.points if update.points is not None else [(p[0], p[1]) for p in element.points]
    confidence = update.confidence if update.confidence is not None else element.confidence
    try:
        check_element(cls=cls, points=points, source=element.source, confidence=confidence)
    except ValueError as error:
        raise InvalidInputError("points" if update.points is not None else "class", str(error)) from None
    check_in_extent(box=cached_extent(session=session, site_id=site_id), points=points, margin_m=margin_m)
    before = snapshot(element)
    element.cls, element.confidence = cls, confidence
    _set_points(element, points)
    return commit_change(session, element, username=username, action="update", before=before)


def delete_element(
    *, session: Session, site_id: int, element_id: int, version: int, username: str, role: str
) -> Element:
    """Soft delete: the element is marked deleted (and logged), never removed."""
    element = element_for_write(
        session=session,
        site_id=site_id,
        element_id=element_id,
        version=version,
        username=username,
        role=role,
        action="delete",
    )
    if element.deleted:
        raise ConflictError(f"element {element_id} is already deleted")
    before = snapshot(element)
    element.deleted = True
    return commit_change(session, element, username=username, action="delete", before=before)
