"""Proposal refresh: a new proposer run replaces the site's untouched proposals; every change is in the edit log.

An element is replaceable when nobody has reviewed or edited it: source `proposal` at version 1 (only its
`create` entry in the log), state `proposed` (or pre-accepted and not yet looked at by a lead), live, and held
by no lease. The replacement is one transaction: a conditional soft delete of exactly those rows (one edited
or leased meanwhile is left alone), logged as `refresh`, then the new proposals, less those that a kept element
of the same class already covers (reviewed work is never proposed twice). New proposals whose confidence is at
or above the pre-accept threshold enter as `accepted` with `preaccepted` set; a share of those is flagged
`qa_sample` for the lead's QA queue. The rest wait in the annotators' queue, lowest confidence first.
"""

import logging
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from pydantic import ValidationError
from shapely import STRtree
from shapely.geometry import LineString
from sqlalchemy import ColumnElement, and_, or_, select, update
from sqlalchemy.orm import Session

from annotations.schema import AnnotationSet
from app.backend.clock import utc_now
from app.backend.crud.elements import (
    Preaccept,
    check_in_site,
    log_change,
    mark_preaccepted,
    new_element,
    snapshot,
)
from app.backend.crud.sites import get_site
from app.backend.errors import InvalidInputError
from app.backend.models import EditLog, Element, Site
from app.backend.models_review import Lease
from app.backend.schemas import ElementCreate

logger = logging.getLogger(__name__)

COVER_DISTANCE_M = 1.5
"""A new proposal lying within this distance of a kept element of its class ..."""
COVER_SHARE = 0.8
"""... over at least this share of its length is already covered, and is dropped."""


@dataclass(frozen=True)
class RefreshSummary:
    """What a refresh did to the site's elements."""

    replaced: int
    """Untouched proposals soft-deleted."""
    added: int
    preaccepted: int
    qa_sample: int
    covered: int
    """New proposals dropped because a kept element covers them."""
    invalid: int
    """New proposals dropped as invalid geometry or outside the site."""


def _untouched(site_id: int) -> ColumnElement[bool]:
    """Live, unleased proposals that nobody has reviewed or edited (version 1: only their `create` entry)."""
    held = select(Lease.active_element_id).where(Lease.active_element_id.is_not(None))
    return and_(
        Element.site_id == site_id,
        Element.source == "proposal",
        Element.version == 1,
        Element.deleted.is_(False),
        or_(Element.state == "proposed", and_(Element.state == "accepted", Element.preaccepted.is_(True))),
        Element.id.not_in(held),
    )


def _retire_untouched(session: Session, site_id: int, username: str) -> int:
    """Soft-delete the site's untouched proposals with a `refresh` log entry each; how many."""
    rows = {row.id: snapshot(row) for row in session.scalars(select(Element).where(_untouched(site_id)))}
    if not rows:
        return 0
    now = utc_now()
    retired = session.scalars(
        update(Element)
        .where(Element.id.in_(sorted(rows)), _untouched(site_id))
        .values(deleted=True, version=Element.version + 1, author=username, updated_at=now)
        .returning(Element.id)
        .execution_options(synchronize_session=False)
    ).all()
    for element_id in retired:
        before = rows[element_id]
        session.add(
            EditLog(
                element_id=element_id,
                version=2,
                username=username,
                at=now,
                action="refresh",
                before=before,
                after={**before, "deleted": True},
            )
        )
    return len(retired)


def _kept_index(session: Session, site_id: int) -> tuple[STRtree, list[tuple[str, LineString]]]:
    """The site's live elements (after retiring) as lines in a spatial index."""
    kept = [
        (cls, LineString(points))
        for cls, points in session.execute(
            select(Element.cls, Element.points).where(Element.site_id == site_id, Element.deleted.is_(False))
        )
    ]
    return STRtree([line for _cls, line in kept]), kept


def _is_covered(line: LineString, cls: str, tree: STRtree, kept: Sequence[tuple[str, LineString]]) -> bool:
    """Whether kept elements of class `cls` run within COVER_DISTANCE_M along most of `line`."""
    near = [kept[int(k)][1] for k in tree.query(line.buffer(COVER_DISTANCE_M)) if kept[int(k)][0] == cls]
    if not near or line.length == 0:
        return False
    zone = near[0].buffer(COVER_DISTANCE_M)
    for other in near[1:]:
        zone = zone.union(other.buffer(COVER_DISTANCE_M))
    return bool(line.intersection(zone).length >= COVER_SHARE * line.length)


def _site_offset(site: Site, proposals: AnnotationSet) -> np.ndarray:
    """What to add to the proposals' site metres to get this site's metres (their origins may differ)."""
    return np.asarray(proposals.georeference.site_origin_xy) - (site.site_origin_x, site.site_origin_y)


def _candidates(site: Site, proposals: AnnotationSet, margin_m: float) -> tuple[list[ElementCreate], int]:
    """The proposals as validated element inputs in this site's metres, and how many were invalid."""
    offset = _site_offset(site, proposals)
    valid, invalid = [], 0
    for element in proposals.elements:
        points = [(float(x), float(y)) for x, y in element.xy()[:, :2] + offset]
        try:
            element_in = ElementCreate.model_validate(
                {
                    "class": element.cls,
                    "points": points,
                    "confidence": element.confidence,
                    "source": "proposal",
                    "model": element.author,
                }
            )
            check_in_site(site=site, points=element_in.points, margin_m=margin_m)
        except (ValidationError, InvalidInputError) as error:
            logger.info("refresh: proposal %s dropped: %s", element.id, error)
            invalid += 1
            continue
        valid.append(element_in)
    return valid, invalid


def _add_proposals(
    session: Session,
    site: Site,
    elements_in: Sequence[ElementCreate],
    *,
    username: str,
    preaccept: Preaccept | None,
) -> list[Element]:
    """Store new proposals (confident ones pre-accepted, see `mark_preaccepted`), each logged."""
    elements = [new_element(site, element_in, username=username) for element_in in elements_in]
    if preaccept is not None:
        mark_preaccepted(elements, preaccept)
    session.add_all(elements)
    session.flush()
    for element in elements:
        log_change(session, element, username=username, action="create", before=None)
    return elements


def refresh_proposals(
    *,
    session: Session,
    site_id: int,
    proposals: AnnotationSet,
    username: str,
    threshold: float | None,
    qa_share: float,
    seed: int,
    margin_m: float,
) -> RefreshSummary:
    """Replace the site's untouched proposals by `proposals` (one transaction; see the module docstring)."""
    site = get_site(session=session, site_id=site_id)
    candidates, invalid = _candidates(site, proposals, margin_m)
    replaced = _retire_untouched(session, site_id, username)
    session.flush()
    tree, kept = _kept_index(session, site_id)
    fresh = [c for c in candidates if not _is_covered(LineString(c.points), c.cls, tree, kept)]
    preaccept = None if threshold is None else Preaccept(threshold, qa_share, seed)
    elements = _add_proposals(session, site, fresh, username=username, preaccept=preaccept)
    session.commit()
    summary = RefreshSummary(
        replaced=replaced,
        added=len(elements),
        preaccepted=sum(e.preaccepted for e in elements),
        qa_sample=sum(e.qa_sample for e in elements),
        covered=len(candidates) - len(fresh),
        invalid=invalid,
    )
    logger.info("site %d refreshed: %s", site_id, summary)
    return summary
