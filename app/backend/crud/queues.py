"""Queues: the lead's review queue and annotators' work items held by leases.

Review queue order: confidence ascending, elements without a confidence (drawn by people) last, then id.

Work items: `next_work_item` leases one element at a time. Candidates are live elements of the site that no
active lease holds and that the requester does not already hold, in this order:
1. `returned` elements whose last annotator (the latest edit-log entry by a user with role `annotator`) is the
   requester, oldest id first: returned work goes to the front of its annotator's queue; then returned elements
   no annotator ever edited (pre-accepted by the model and returned by a lead's QA), for anyone;
2. `proposed` elements with lint errors (the caller passes their ids), then the other `proposed` ones; each
   group lowest confidence first, human-made (no confidence) last.
Returned elements of other annotators are never handed out.

Region work items: `next_region` leases, in one transaction, every free `proposed` element whose bounding-box
centre lies in the grid cell (of side `cell_m`, site metres) holding the element `next_work_item` would hand out
first; each element gets its own lease, so reviews, expiry and release work as for single elements.

Requests for work items of one site take turns: each attempt first locks the site's row (`FOR NO KEY UPDATE` on
PostgreSQL, which leaves inserts that merely reference the site unblocked; SQLite has a single writer anyway, taken
by the reclaim below), so a request chooses its candidate after the leases of the requests before it are committed.
Without that turn, every concurrent request would choose the same first candidate, all but one would lose, and
under enough annotators at once a request could lose every attempt. The guard against two annotators getting one
element stays the UNIQUE `leases.active_element_id`: an insert that still loses a race fails with IntegrityError
and the request looks again. Expired leases are reclaimed (their
`active_element_id` cleared) at the start of each request, so an abandoned item is free again. While a lease
holds an element, only its holder (or a lead) may change it: `crud.leases.check_lease`, which every element write
passes.
"""

import logging
import math
from collections.abc import Callable, Collection, Sequence
from datetime import datetime, timedelta

from sqlalchemy import ColumnElement, Select, func, select, update
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session

from app.backend.clock import as_utc
from app.backend.crud import leases as lease_rules
from app.backend.crud.elements import public
from app.backend.crud.sites import get_site
from app.backend.errors import ConflictError, ForbiddenError, NotFoundError
from app.backend.models import EditLog, Element, Site, User
from app.backend.models_review import Lease
from app.backend.schemas_quality import LintFindingPublic
from app.backend.schemas_review import LeasePublic

logger = logging.getLogger(__name__)

CANDIDATES_PER_TRY = 16
"""How many candidates one attempt considers before looking again."""
MAX_ATTEMPTS = 8
Box = tuple[float, float, float, float]
"""xmin, ymin, xmax, ymax in site metres."""


def review_queue(
    *,
    session: Session,
    site_id: int,
    cls: str | None = None,
    state: str | None = None,
    author: str | None = None,
    bbox: tuple[float, float, float, float] | None = None,
    only_ids: Collection[int] | None = None,
    qa: bool = False,
    limit: int = 100,
    offset: int = 0,
) -> tuple[int, list[Element]]:
    """The total count and one page of live elements, lowest confidence first and no confidence last;
    `only_ids` restricts the queue to those elements (e.g. the ones with lint findings); `qa` to the
    pre-accepted elements sampled for the lead's QA that are still awaiting a lead (state `accepted`)."""
    get_site(session=session, site_id=site_id)
    conditions: list[ColumnElement[bool]] = [Element.site_id == site_id, Element.deleted.is_(False)]
    if only_ids is not None:
        conditions.append(Element.id.in_(sorted(only_ids)))
    if qa:
        conditions += [Element.qa_sample.is_(True), Element.state == "accepted"]
    if cls is not None:
        conditions.append(Element.cls == cls)
    if state is not None:
        conditions.append(Element.state == state)
    if author is not None:
        conditions.append(Element.author == author)
    if bbox is not None:
        xmin, ymin, xmax, ymax = bbox
        conditions += [Element.xmax >= xmin, Element.xmin <= xmax, Element.ymax >= ymin, Element.ymin <= ymax]
    total = session.scalar(select(func.count()).select_from(Element).where(*conditions)) or 0
    query = (
        select(Element)
        .where(*conditions)
        .order_by(Element.confidence.is_(None), Element.confidence, Element.id)
        .limit(limit)
        .offset(offset)
    )
    return int(total), list(session.scalars(query))


def lease_public(
    session: Session,
    lease: Lease,
    *,
    now: datetime | None = None,
    lint: Sequence[LintFindingPublic] = (),
) -> LeasePublic:
    """The API view of a lease with its element (and the lint findings involving it, when given)."""
    now = now or lease_rules.clock()
    element = session.get(Element, lease.element_id)
    if element is None:
        raise NotFoundError(f"element {lease.element_id} of lease {lease.id} not found")
    active = lease.active_element_id is not None and as_utc(lease.expires_at) > now
    return LeasePublic(
        id=lease.id,
        site_id=lease.site_id,
        element_id=lease.element_id,
        username=lease.username,
        acquired_at=as_utc(lease.acquired_at),
        expires_at=as_utc(lease.expires_at),
        released_at=None if lease.released_at is None else as_utc(lease.released_at),
        active=active,
        element=public(element),
        lint=list(lint),
    )


def _reclaim_expired(session: Session, *, site_id: int, now: datetime) -> None:
    """Free the elements of expired leases (the row stays, as history). Also opens the write transaction."""
    session.execute(
        update(Lease)
        .where(Lease.site_id == site_id, Lease.active_element_id.is_not(None), Lease.expires_at <= now)
        .values(active_element_id=None)
    )


def _annotator_edits() -> Select[int, int]:
    """Per element, the id of its latest edit-log entry made by a user with role `annotator`."""
    return (
        select(EditLog.element_id, func.max(EditLog.id).label("log_id"))
        .join(User, User.username == EditLog.username)
        .where(User.role == "annotator")
        .group_by(EditLog.element_id)
    )


def _returned_unowned(site_id: int) -> Select[Element]:
    """Returned elements no annotator ever edited (pre-accepted ones a lead's QA sent back): anyone's work."""
    edited = _annotator_edits().subquery()
    return (
        select(Element)
        .where(
            Element.site_id == site_id,
            Element.state == "returned",
            Element.id.not_in(select(edited.c.element_id)),
        )
        .order_by(Element.id)
    )


def _returned_to(site_id: int, username: str) -> Select[Element]:
    """Returned elements whose latest edit by an annotator was made by `username`."""
    last_annotator_edit = _annotator_edits().subquery()
    return (
        select(Element)
        .join(last_annotator_edit, last_annotator_edit.c.element_id == Element.id)
        .join(EditLog, EditLog.id == last_annotator_edit.c.log_id)
        .where(Element.site_id == site_id, Element.state == "returned", EditLog.username == username)
        .order_by(Element.id)
    )


def _candidates(
    session: Session, *, site_id: int, username: str, flagged_ids: Collection[int]
) -> list[Element]:
    """Unleased elements for `username`, in queue order (see the module docstring)."""
    held = select(Lease.active_element_id).where(Lease.active_element_id.is_not(None))
    free = (Element.deleted.is_(False), Element.id.not_in(held))
    returned = _returned_to(site_id, username).where(*free).limit(CANDIDATES_PER_TRY)
    unowned = _returned_unowned(site_id).where(*free).limit(CANDIDATES_PER_TRY)
    proposed = (
        select(Element)
        .where(Element.site_id == site_id, Element.state == "proposed", *free)
        .order_by(
            Element.id.not_in(sorted(flagged_ids)),
            Element.confidence.is_(None),
            Element.confidence,
            Element.id,
        )
        .limit(CANDIDATES_PER_TRY)
    )
    return [*session.scalars(returned), *session.scalars(unowned), *session.scalars(proposed)]


def _new_lease(site_id: int, element: Element, username: str, now: datetime, lease_s: int) -> Lease:
    return Lease(
        site_id=site_id,
        element_id=element.id,
        active_element_id=element.id,
        username=username,
        acquired_at=now,
        expires_at=now + timedelta(seconds=lease_s),
    )


def _take_turn(session: Session, site_id: int) -> None:
    """Wait for the work-item requests of this site that are already choosing (see the module docstring)."""
    session.execute(select(Site.id).where(Site.id == site_id).with_for_update(key_share=True))


def _lease_next(
    session: Session,
    *,
    site_id: int,
    username: str,
    flagged_ids: Collection[int],
    leases_for: Callable[[Element, datetime], list[Lease]],
) -> tuple[Element, list[Lease]] | None:
    """Lease what `leases_for` makes of the first candidate in one transaction, looking again when another
    request took one of its elements first; (that candidate, the leases), None when there is no work left."""
    get_site(session=session, site_id=site_id)
    for _attempt in range(MAX_ATTEMPTS):
        _take_turn(session, site_id)
        now = lease_rules.clock()
        _reclaim_expired(session, site_id=site_id, now=now)
        candidates = _candidates(session, site_id=site_id, username=username, flagged_ids=flagged_ids)
        if not candidates:
            session.commit()
            return None
        leases = leases_for(candidates[0], now)
        session.add_all(leases)
        try:
            session.commit()
        except IntegrityError:
            session.rollback()  # another request leased one of them first: look again
            continue
        return candidates[0], leases
    raise ConflictError("queue: too many concurrent requests for work items; try again")


def next_work_item(
    *, session: Session, site_id: int, username: str, lease_s: int, flagged_ids: Collection[int] = ()
) -> Lease | None:
    """Lease the next work item to `username` for `lease_s` seconds (proposals in `flagged_ids`, those with
    lint errors, before the others); None when there is no work left."""
    found = _lease_next(
        session,
        site_id=site_id,
        username=username,
        flagged_ids=flagged_ids,
        leases_for=lambda element, now: [_new_lease(site_id, element, username, now, lease_s)],
    )
    if found is None:
        return None
    lease = found[1][0]
    logger.info("leased element %s to %s until %s", lease.element_id, username, lease.expires_at)
    return lease


def _region_members(session: Session, site_id: int, seed: Element, cell: Box) -> list[Element]:
    """The seed and the free proposals centred in `cell`, by id."""
    held = select(Lease.active_element_id).where(Lease.active_element_id.is_not(None))
    cx, cy = (Element.xmin + Element.xmax) / 2, (Element.ymin + Element.ymax) / 2
    query = select(Element).where(
        Element.site_id == site_id,
        Element.state == "proposed",
        Element.deleted.is_(False),
        Element.id.not_in(held),
        Element.id != seed.id,
        cx >= cell[0],
        cx < cell[2],
        cy >= cell[1],
        cy < cell[3],
    )
    return [seed, *session.scalars(query.order_by(Element.id))]


def _cell_of(element: Element, cell_m: float) -> Box:
    """The grid cell holding the element's bounding-box centre."""
    col = math.floor((element.xmin + element.xmax) / 2 / cell_m)
    row = math.floor((element.ymin + element.ymax) / 2 / cell_m)
    return (col * cell_m, row * cell_m, (col + 1) * cell_m, (row + 1) * cell_m)


def next_region(
    *,
    session: Session,
    site_id: int,
    username: str,
    lease_s: int,
    cell_m: float,
    flagged_ids: Collection[int] = (),
) -> tuple[Box, list[Lease]] | None:
    """Lease the next region work item to `username` (see the module docstring): its cell and one lease per
    element; None when there is no work left."""

    def leases_for(seed: Element, now: datetime) -> list[Lease]:
        members = _region_members(session, site_id, seed, _cell_of(seed, cell_m))
        return [_new_lease(site_id, element, username, now, lease_s) for element in members]

    found = _lease_next(
        session, site_id=site_id, username=username, flagged_ids=flagged_ids, leases_for=leases_for
    )
    if found is None:
        return None
    seed, leases = found
    cell = _cell_of(seed, cell_m)
    logger.info("leased region %s (%d elements) to %s", cell, len(leases), username)
    return cell, leases


def get_lease(*, session: Session, lease_id: int) -> Lease:
    """The lease with this id; NotFoundError otherwise."""
    lease = session.get(Lease, lease_id)
    if lease is None:
        raise NotFoundError(f"lease {lease_id} not found")
    return lease


def read_lease(*, session: Session, lease_id: int, username: str, role: str) -> Lease:
    """The lease, for its holder, a lead or an admin."""
    lease = get_lease(session=session, lease_id=lease_id)
    if lease.username != username and role not in ("lead", "admin"):
        raise ForbiddenError(f"lease {lease_id} belongs to {lease.username!r}")
    return lease


def release_lease(*, session: Session, lease_id: int, username: str, role: str) -> Lease:
    """Give the element back; the holder, a lead or an admin may release. Releasing twice is a no-op."""
    lease = read_lease(session=session, lease_id=lease_id, username=username, role=role)
    if lease.released_at is None:
        lease.released_at = lease_rules.clock()
        lease.active_element_id = None
        session.commit()
        logger.info("lease %s released by %s", lease_id, username)
    return lease


def renew_lease(*, session: Session, lease_id: int, username: str, lease_s: int) -> Lease:
    """Extend the holder's unexpired lease to `lease_s` seconds from now; 409 when released or expired."""
    lease = get_lease(session=session, lease_id=lease_id)
    if lease.username != username:
        raise ForbiddenError(f"lease {lease_id} belongs to {lease.username!r}; only its holder may renew it")
    now = lease_rules.clock()
    result = session.execute(
        update(Lease)
        .where(Lease.id == lease_id, Lease.active_element_id.is_not(None), Lease.expires_at > now)
        .values(expires_at=now + timedelta(seconds=lease_s))
        .execution_options(synchronize_session=False)
    )
    if result.rowcount != 1:  # type: ignore[attr-defined]
        session.rollback()
        raise ConflictError(f"lease {lease_id} was released or has expired; ask for the next work item")
    session.commit()
    session.refresh(lease)
    return lease
