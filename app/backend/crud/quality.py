"""Map quality over the database: lint of a site's live elements (cached), proposal diffs and annotator figures.

Every function takes keyword-only arguments; none writes to the database.
"""

import logging
import threading
from collections import defaultdict
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from shapely.geometry import Polygon, box
from sqlalchemy import func, select
from sqlalchemy.orm import Session

from app.backend.crud.elements import get_element
from app.backend.crud.sites import get_site, site_extent
from app.backend.errors import NotFoundError
from app.backend.models import EditLog, Element, Site
from app.backend.quality import (
    AnnotatorFigures,
    ElementView,
    LintConfig,
    LintFinding,
    ProposalDiff,
    ReviewEvent,
    annotator_figures,
    lint,
    proposal_diff,
)
from app.backend.schemas_quality import ClassDiffSummary, LintFindingPublic, LintReport, ProposalDiffPublic

logger = logging.getLogger(__name__)

REVIEWED_STATES = ("accepted", "fixed", "approved", "returned")
"""States whose geometry an annotator has looked at: the ones proposal diffs are summarised over."""
FIGURE_STATES = frozenset({"accepted", "fixed", "rejected"})
"""Review actions counted in the annotator figures."""

LintKey = tuple[int, int]
"""(elements ever stored, sum of their versions): every create, edit or delete changes it."""
Box = tuple[float, float, float, float]
"""xmin, ymin, xmax, ymax in site metres."""
INCREMENTAL_MAX_CHANGES = 64
"""Up to this many changed elements, a cached report is patched around them instead of linting the site."""


@dataclass(frozen=True)
class CachedLint:
    """A full-site report and the live elements (id -> version, bounding box) it was made from."""

    key: LintKey
    elements: dict[int, tuple[int, Box]]
    report: LintReport


@dataclass
class LintCache:
    """The last full-site lint report per site; after edits it is patched around the changed elements."""

    entries: dict[int, CachedLint] = field(default_factory=dict)
    lock: threading.Lock = field(default_factory=threading.Lock)

    def get(self, site_id: int) -> CachedLint | None:
        """The site's last full-site report, whatever state it was made for."""
        with self.lock:
            return self.entries.get(site_id)

    def put(self, site_id: int, entry: CachedLint) -> None:
        """Remember a full-site report."""
        with self.lock:
            self.entries[site_id] = entry


def _lint_key(session: Session, site_id: int) -> LintKey:
    """A key that changes whenever any element of the site is created or changed (each change bumps a version)."""
    count, total = session.execute(
        select(func.count(), func.coalesce(func.sum(Element.version), 0)).where(Element.site_id == site_id)
    ).one()
    return int(count), int(total)


def _live_elements(session: Session, site_id: int) -> dict[int, tuple[int, Box]]:
    """Version and bounding box of every live element of the site (no geometry loaded)."""
    query = select(Element.id, Element.version, Element.xmin, Element.ymin, Element.xmax, Element.ymax).where(
        Element.site_id == site_id, Element.deleted.is_(False)
    )
    return {row[0]: (row[1], (row[2], row[3], row[4], row[5])) for row in session.execute(query)}


def _changed_box(before: dict[int, tuple[int, Box]], after: dict[int, tuple[int, Box]]) -> Box | None:
    """The box around the old and new extent of every element added, changed or removed; None if none."""
    boxes = [entry[1] for k, entry in before.items() if after.get(k) != entry]
    boxes += [entry[1] for k, entry in after.items() if before.get(k) != entry]
    if not boxes:
        return None
    corners = np.asarray(boxes)
    return (corners[:, 0].min(), corners[:, 1].min(), corners[:, 2].max(), corners[:, 3].max())


def _public_finding(finding: LintFinding) -> LintFindingPublic:
    """A finding with the database ids back as integers."""
    return LintFindingPublic(
        code=finding.code,
        severity=finding.severity,
        element_ids=[int(element_id) for element_id in finding.element_ids],
        location_xy=finding.location_xy,
        message=finding.message,
    )


def _in_bbox(xy: Sequence[float], bbox: tuple[float, float, float, float]) -> bool:
    """Whether a point lies in xmin, ymin, xmax, ymax."""
    return bbox[0] <= xy[0] <= bbox[2] and bbox[1] <= xy[1] <= bbox[3]


def _lint_findings(
    session: Session, site: Site, bbox: Box | None, config: LintConfig
) -> tuple[int, list[LintFindingPublic]]:
    """Lint the live elements (those within reach of `bbox` when given, keeping only findings inside it);
    the number of elements linted and the findings."""
    query = select(Element.id, Element.cls, Element.points).where(
        Element.site_id == site.id, Element.deleted.is_(False)
    )
    if bbox is not None:
        reach = _reach(config)
        xmin, ymin, xmax, ymax = bbox[0] - reach, bbox[1] - reach, bbox[2] + reach, bbox[3] + reach
        query = query.where(
            Element.xmax >= xmin, Element.xmin <= xmax, Element.ymax >= ymin, Element.ymin <= ymax
        )
    views = [
        ElementView(id=str(element_id), cls=cls, points=np.asarray(points, dtype=float))
        for element_id, cls, points in session.execute(query.order_by(Element.id))
    ]
    extent = site_extent(site)
    region: Polygon = box(extent.xmin, extent.ymin, extent.xmax, extent.ymax)
    findings = [_public_finding(finding) for finding in lint(views, config=config, region=region)]
    if bbox is not None:
        findings = [finding for finding in findings if _in_bbox(finding.location_xy, bbox)]
    return len(views), findings


def _reach(config: LintConfig) -> float:
    """How far from an element a finding it takes part in may lie."""
    return max(config.end_connect_m, config.spacing_search_m, config.break_gap_m)


def _patched(
    session: Session, site: Site, cached: CachedLint, elements: dict[int, tuple[int, Box]], config: LintConfig
) -> list[LintFindingPublic] | None:
    """The cached findings with those near changed elements linted again; None when too much changed.

    A finding involving a changed element lies within `_reach` of it, so re-linting the changed area grown by
    that reach (old and new extents) and keeping the cached findings outside it gives the full-site result."""
    changed = set(cached.elements.items()) ^ set(elements.items())
    if len(changed) > 2 * INCREMENTAL_MAX_CHANGES:
        return None
    area = _changed_box(cached.elements, elements)
    if area is None:
        return cached.report.findings
    reach = _reach(config)
    grown = (area[0] - reach, area[1] - reach, area[2] + reach, area[3] + reach)
    _count, fresh = _lint_findings(session, site, grown, config)
    kept = [finding for finding in cached.report.findings if not _in_bbox(finding.location_xy, grown)]
    return kept + fresh


def lint_site(
    *,
    session: Session,
    site_id: int,
    cache: LintCache,
    bbox: Box | None = None,
    config: LintConfig = LintConfig(),  # noqa: B008 - frozen, so a shared default is safe
) -> LintReport:
    """Lint the site's live elements (the site extent is the region where ends may stop).

    A full-site report is cached; after edits it is patched around the changed elements (the whole site is
    linted again only when many changed). With `bbox`, elements near it are linted and only findings located
    inside it are returned (not cached).
    """
    site = get_site(session=session, site_id=site_id)
    if bbox is not None:
        count, findings = _lint_findings(session, site, bbox, config)
        return LintReport(site_id=site_id, element_count=count, findings=findings)
    key = _lint_key(session, site_id)
    cached = cache.get(site_id)
    if cached is not None and cached.key == key:
        return cached.report
    elements = _live_elements(session, site_id)
    patched = None if cached is None else _patched(session, site, cached, elements, config)
    findings = patched if patched is not None else _lint_findings(session, site, None, config)[1]
    report = LintReport(site_id=site_id, element_count=len(elements), findings=findings)
    cache.put(site_id, CachedLint(key, elements, report))
    logger.info(
        "lint site %d (%s): %d findings over %d elements",
        site_id,
        "patched" if patched is not None else "full",
        len(findings),
        len(elements),
    )
    return report


def element_findings(
    *, session: Session, site_id: int, element_id: int, cache: LintCache
) -> list[LintFindingPublic]:
    """The findings of the (cached) full-site lint that involve this element."""
    get_element(session=session, site_id=site_id, element_id=element_id)
    report = lint_site(session=session, site_id=site_id, cache=cache)
    return [finding for finding in report.findings if element_id in finding.element_ids]


def findings_by_element(report: LintReport) -> dict[int, list[LintFindingPublic]]:
    """The report's findings grouped under every element they involve."""
    grouped: dict[int, list[LintFindingPublic]] = defaultdict(list)
    for finding in report.findings:
        for element_id in finding.element_ids:
            grouped[element_id].append(finding)
    return dict(grouped)


def _diff_of(element: Element) -> ProposalDiff:
    """The proposal-to-current diff of an element with a proposal snapshot."""
    proposal = element.proposal or {}
    return proposal_diff(
        proposal["points"], element.points, proposal_cls=proposal["class"], final_cls=element.cls
    )


def element_diff(*, session: Session, site_id: int, element_id: int) -> ProposalDiffPublic:
    """How the element moved away from its proposal; NotFoundError when it never was a proposal."""
    element = get_element(session=session, site_id=site_id, element_id=element_id)
    if element.proposal is None:
        raise NotFoundError(
            f"element {element_id} was drawn by hand (source {element.source!r}); it has no proposal to diff against"
        )
    diff = _diff_of(element)
    return ProposalDiffPublic(
        element_id=element.id,
        proposal_class=str(element.proposal["class"]),
        current_class=element.cls,
        state=element.state,
        **diff.__dict__,
    )


def diff_summary(*, session: Session, site_id: int) -> list[ClassDiffSummary]:
    """Per proposal class, over live reviewed proposals: unchanged count, mean Chamfer, vertex changes.
    Pre-accepted proposals still awaiting a lead count once a lead has decided (nobody reviewed them yet)."""
    get_site(session=session, site_id=site_id)
    query = select(Element).where(
        Element.site_id == site_id,
        Element.deleted.is_(False),
        Element.proposal.is_not(None),
        Element.state.in_(REVIEWED_STATES),
        ~(Element.preaccepted.is_(True) & (Element.state == "accepted")),
    )
    diffs: dict[str, list[ProposalDiff]] = defaultdict(list)
    for element in session.scalars(query):
        if element.proposal is None:  # a JSON null stored by hand; the SQL test cannot tell it apart
            continue
        diffs[str(element.proposal["class"])].append(_diff_of(element))
    return [
        ClassDiffSummary(
            cls=cls,
            elements=len(rows),
            unchanged=sum(diff.unchanged for diff in rows),
            class_changed=sum(diff.class_changed for diff in rows),
            mean_chamfer_m=float(np.mean([diff.chamfer_m for diff in rows])),
            vertices_moved=sum(diff.vertices_moved for diff in rows),
            vertices_added=sum(diff.vertices_added for diff in rows),
            vertices_removed=sum(diff.vertices_removed for diff in rows),
        )
        for cls, rows in sorted(diffs.items())
    ]


def _event(entry: EditLog, proposal: dict[str, object] | None) -> ReviewEvent | None:
    """The review event of one log entry, or None for entries the figures do not count."""
    after = entry.after
    if entry.action == "create" and after.get("source") == "human":
        return ReviewEvent(author=entry.username, cls=str(after["class"]), action="created", at=entry.at)
    if entry.action != "review" or after.get("state") not in FIGURE_STATES:
        return None
    diff = None
    if proposal is not None:
        diff = proposal_diff(
            proposal["points"],  # type: ignore[arg-type]  # JSON list of [x, y]
            after["points"],
            proposal_cls=str(proposal["class"]),
            final_cls=str(after["class"]),
        )
    return ReviewEvent(
        author=entry.username, cls=str(after["class"]), action=after["state"], at=entry.at, diff=diff
    )


def site_figures(*, session: Session, site_id: int) -> list[AnnotatorFigures]:
    """Figures per annotator and class from the site's edit log (reviews, and elements drawn by hand)."""
    get_site(session=session, site_id=site_id)
    query = (
        select(EditLog, Element.proposal)
        .join(Element, EditLog.element_id == Element.id)
        .where(Element.site_id == site_id, EditLog.action.in_(("create", "review")))
        .order_by(EditLog.at, EditLog.id)
    )
    events = [
        event for entry, proposal in session.execute(query) if (event := _event(entry, proposal)) is not None
    ]
    return annotator_figures(events)
