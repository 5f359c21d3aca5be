"""Review transitions and history: state changes by role, the edit log, and restoring earlier versions."""

import logging

from sqlalchemy import select, update
from sqlalchemy.orm import Session

from app.backend.clock import utc_now
from app.backend.crud.elements import _set_points, commit_change, element_for_write, get_element, snapshot
from app.backend.errors import ConflictError, ForbiddenError, NotFoundError
from app.backend.models import EditLog, Element
from app.backend.models_review import Lease

logger = logging.getLogger(__name__)

ANNOTATOR_TRANSITIONS: dict[str, frozenset[str]] = {
    "proposed": frozenset({"accepted", "fixed", "rejected"}),
    "returned": frozenset({"accepted", "fixed", "rejected"}),
}
"""Annotators verify proposals (and work sent back to them)."""
LEAD_TRANSITIONS: dict[str, frozenset[str]] = {
    "accepted": frozenset({"approved", "returned"}),
    "fixed": frozenset({"approved", "returned"}),
    "approved": frozenset({"returned"}),
}
"""Leads approve or return what annotators verified, and reopen approved work by returning it: annotators may
not change approved work themselves (`crud.elements.element_for_write`)."""
LEAD_STATES = frozenset({"approved", "returned"})
VERIFIED_STATES = frozenset({"accepted", "fixed", "rejected"})
"""An annotator's verdict: the work item is done, so its lease ends with the review."""


def allowed_targets(state: str, role: str) -> frozenset[str]:
    """States a user of `role` may move an element in `state` to (leads and admins may do annotators' work)."""
    targets = ANNOTATOR_TRANSITIONS.get(state, frozenset())
    if role in ("lead", "admin"):
        targets = targets | LEAD_TRANSITIONS.get(state, frozenset())
    return targets


def review_element(
    *, session: Session, site_id: int, element_id: int, target: str, version: int, username: str, role: str
) -> Element:
    """Move an element to `target`; 403 for a lead-only state asked by an annotator, 409 for an invalid move."""
    if target in LEAD_STATES and role not in ("lead", "admin"):
        raise ForbiddenError(f"state: only a lead may set {target!r}")
    element = element_for_write(
        session=session,
        site_id=site_id,
        element_id=element_id,
        version=version,
        username=username,
        role=role,
        action="review",
    )
    if element.deleted:
        raise ConflictError(f"element {element_id} is deleted; restore a version first")
    if target not in allowed_targets(element.state, role):
        allowed = sorted(allowed_targets(element.state, role)) or "none"
        raise ConflictError(
            f"state: cannot go from {element.state!r} to {target!r}; allowed from {element.state!r}: {allowed}"
        )
    if (
        target in VERIFIED_STATES
    ):  # before the element changes: an autoflush here would bump its version twice
        _release_leases_of(session, element_id)
    before = snapshot(element)
    element.state = target
    return commit_change(session, element, username=username, action="review", before=before)


def _release_leases_of(session: Session, element_id: int) -> None:
    """End the active lease on a reviewed element, in the review's own transaction (undone with it on 409)."""
    session.execute(
        update(Lease)
        .where(Lease.active_element_id == element_id)
        .values(active_element_id=None, released_at=utc_now())
        .execution_options(synchronize_session=False)
    )


def element_history(*, session: Session, site_id: int, element_id: int) -> list[EditLog]:
    """The element's edit log, oldest first."""
    get_element(session=session, site_id=site_id, element_id=element_id)
    query = select(EditLog).where(EditLog.element_id == element_id).order_by(EditLog.version, EditLog.id)
    return list(session.scalars(query))


def restore_version(
    *, session: Session, site_id: int, element_id: int, restore: int, version: int, username: str, role: str
) -> Element:
    """Make the content of an earlier version the new current version (a new log entry; nothing erased).

    Only a lead (or admin) may restore across a lead's decision: an annotator can neither undo an approval or
    return nor bring one back, as the review transitions forbid the same moves."""
    element = element_for_write(
        session=session,
        site_id=site_id,
        element_id=element_id,
        version=version,
        username=username,
        role=role,
        action="restore",
    )
    entry = session.scalar(
        select(EditLog).where(EditLog.element_id == element_id, EditLog.version == restore)
    )
    if entry is None:
        raise NotFoundError(f"element {element_id} has no version {restore}")
    content = entry.after
    if role not in ("lead", "admin") and LEAD_STATES & {element.state, content["state"]}:
        raise ForbiddenError(
            f"state: only a lead may restore between {element.state!r} and {content['state']!r} (a lead's decision)"
        )
    before = snapshot(element)
    element.cls = content["class"]
    _set_points(element, [(p[0], p[1]) for p in content["points"]])
    element.confidence = content["confidence"]
    element.state = content["state"]
    element.deleted = bool(content["deleted"])
    return commit_change(session, element, username=username, action="restore", before=before)
