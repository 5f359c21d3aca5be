"""A site's element changes after a cursor, for followers (the 3D review) that poll instead of re-reading every
element.

The cursor is an `edit_log` id: every change to an element appends a log row in the change's own transaction
(`crud.elements`, `crud.review`, `crud.refresh`), so the rows after a cursor name every element changed since.
A poll returns the site's elements changed after the cursor at their current version (deleted ones as ids), and
as the next cursor the newest id of the whole log, once every smaller id is known to be committed (below); an
idle poll reads that newest id from the log's primary key and answers with no element.

Ids are taken when a row is inserted, not when it commits, so a cursor is safe only if no transaction holding a
smaller id can still commit after the poll has read past it:
- SQLite has one writer at a time (its database lock; `SqliteWriteTurns` within a process): a row's id is taken
  under that lock and committed before the next writer starts, so ids commit in order and nothing is needed.
- PostgreSQL takes ids from a sequence, so a transaction holding id 10 can commit after one holding 11. The poll
  first takes `LOCK TABLE edit_log IN SHARE MODE`, which waits until every transaction writing the log has ended
  (and holds new writers back for the poll's own few milliseconds); at READ COMMITTED, the backend's isolation
  level, the poll's next statement then sees all of them. When a long writer (a proposal refresh) holds the log
  longer than `LOCK_TIMEOUT_MS`, the poll answers "nothing yet" with the same cursor rather than stall edits.
  Edits pay only that short wait: their write path is unchanged.
"""

import logging
from dataclasses import dataclass

from sqlalchemy import case, func, select, text
from sqlalchemy.exc import OperationalError
from sqlalchemy.orm import Session

from app.backend.crud.sites import get_site
from app.backend.models import EditLog, Element

logger = logging.getLogger(__name__)

LOCK_TIMEOUT_MS = 250
"""PostgreSQL: how long a poll waits for the edit log's writers before answering "nothing yet"."""
LOCK_NOT_AVAILABLE = "55P03"
"""PostgreSQL's SQLSTATE for a lock not granted within `lock_timeout`."""


@dataclass(frozen=True)
class ElementChanges:
    """What changed in a site after a cursor."""

    cursor: int
    """The newest edit-log id covered: the `since` of the next poll."""
    elements: list[Element]
    """Created or changed since, at their current version; deleted ones are in `deleted`."""
    deleted: list[int]
    """Ids of elements deleted since (those also created since are left out: the follower never saw them)."""


def element_changes(*, session: Session, site_id: int, since: int) -> ElementChanges:
    """The site's elements changed after edit-log id `since` (0: every element), up to the log's newest id (the
    next cursor). A `since` newer than the whole log (a cursor from another database) is answered with cursor 0
    and no changes: start again from 0."""
    get_site(session=session, site_id=site_id)
    if not _writers_done(session):
        return ElementChanges(since, [], [])
    newest = session.scalar(select(func.max(EditLog.id))) or 0
    if since >= newest:
        session.commit()  # ends the read (and PostgreSQL's lock)
        return ElementChanges(since if since == newest else 0, [], [])
    changed = (
        select(EditLog.element_id, func.max(case((EditLog.action == "create", 1), else_=0)).label("created"))
        .join(Element, EditLog.element_id == Element.id)
        .where(Element.site_id == site_id, EditLog.id > since, EditLog.id <= newest)
        .group_by(EditLog.element_id)
        .subquery()
    )
    rows = session.execute(
        select(Element, changed.c.created)
        .join(changed, changed.c.element_id == Element.id)
        .order_by(Element.id)
    ).all()
    session.commit()
    return ElementChanges(
        newest,
        [element for element, _ in rows if not element.deleted],
        [element.id for element, created in rows if element.deleted and not created],
    )


def _writers_done(session: Session) -> bool:
    """PostgreSQL: wait up to `LOCK_TIMEOUT_MS` until no transaction is writing the edit log (see the module
    docstring); False, with the transaction rolled back, when one still is. SQLite: True at once."""
    if session.get_bind().dialect.name != "postgresql":
        return True
    session.execute(text(f"SET LOCAL lock_timeout = {LOCK_TIMEOUT_MS}"))
    try:
        session.execute(text("LOCK TABLE edit_log IN SHARE MODE"))
    except OperationalError as error:
        if getattr(error.orig, "sqlstate", None) != LOCK_NOT_AVAILABLE:
            raise
        session.rollback()
        logger.debug("edit log still being written after %d ms: no changes reported yet", LOCK_TIMEOUT_MS)
        return False
    return True
