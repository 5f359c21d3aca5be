"""Lease rules shared by the work queue and every element write: the lease clock and the lease guard.

A lease (`models_review.Lease`) holds its element while `active_element_id` is set and `expires_at` lies ahead;
an expired one holds nothing even before the queue reclaims it. While a lease holds an element, only its holder
may change it: another annotator's update, delete, review or restore is refused with 409 naming the holder and
the expiry. Leads and admins may override (they supervise the work); each override is logged at INFO with the
lease, and the edit log names the lead as the author of the change.
"""

import logging
from collections.abc import Callable
from datetime import datetime

from sqlalchemy import select
from sqlalchemy.orm import Session

from app.backend.clock import as_utc, utc_now
from app.backend.errors import ConflictError
from app.backend.models import Element
from app.backend.models_review import Lease

logger = logging.getLogger(__name__)

clock: Callable[[], datetime] = utc_now
"""The time source for leases (tests replace it to make leases expire without sleeping)."""
OVERRIDING_ROLES = frozenset({"lead", "admin"})
"""Roles whose writes go through another user's lease."""


def holding_lease(session: Session, element_id: int, *, now: datetime) -> Lease | None:
    """The unexpired lease holding the element, if any (one indexed lookup: `active_element_id` is unique)."""
    return session.scalar(select(Lease).where(Lease.active_element_id == element_id, Lease.expires_at > now))


def check_lease(session: Session, element: Element, *, username: str, role: str, action: str) -> None:
    """ConflictError naming the holder and the expiry when another user's unexpired lease holds the element and
    `role` may not override it; call before changing the element (the lookup would flush pending changes)."""
    lease = holding_lease(session, element.id, now=clock())
    if lease is None or lease.username == username:
        return
    expires = as_utc(lease.expires_at).isoformat(timespec="seconds")
    if role in OVERRIDING_ROLES:
        logger.info(
            "%s %r overrides lease %s of %r on element %s (until %s) to %s it",
            role,
            username,
            lease.id,
            lease.username,
            element.id,
            expires,
            action,
        )
        return
    raise ConflictError(
        f"lease: element {element.id} is leased to {lease.username!r} until {expires}; "
        "wait until it is released or expires, or ask a lead"
    )
