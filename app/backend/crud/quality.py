"""Map quality over the database: lint of a site's live elements (kept up to date per element), proposal diffs
and annotator figures.

Every function takes keyword-only arguments; none writes to the database.
"""

import logging
import threading
import time
from collections import defaultdict
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from shapely.geometry import box
from sqlalchemy import func, select
from sqlalchemy.orm import Session

from app.backend.crud.elements import get_element
from app.backend.crud.sites import get_site, site_extent
from app.backend.errors import NotFoundError
from app.backend.models import EditLog, Element
from app.backend.quality import (
    AnnotatorFigures,
    ElementView,
    LintConfig,
    LintFinding,
    LintWork,
    ProposalDiff,
    ReviewEvent,
    SiteLint,
    annotator_figures,
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
LOAD_CHUNK = 500
"""Changed elements loaded per query (an IN list of ids)."""


@dataclass
class SiteLintEntry:
    """One site's incremental lint: the element versions it holds, and its report for the state `key`."""

    state: SiteLint
    extent: Box
    config: LintConfig
    versions: dict[int, int] = field(default_factory=dict)
    """Version of each element as the state holds it (elements still pending are missing or older)."""
    key: LintKey | None = None
    """The database state the report is complete for; None while elements are pending."""
    report: LintReport | None = None
    work: LintWork = field(default_factory=LintWork)
    """What the last catch-up linted."""
    lock: threading.Lock = field(default_factory=threading.Lock)
    """Held while the entry catches up with the database: one request lints, the others wait for its report."""


@dataclass
class LintCache:
    """Per site, the lint kept up to date element by element (`SiteLint`), and its last report.

    `budget_s` bounds the linting one request does (None: no bound); what is left is linted by the next
    requests, and reports say how many elements are pending.
    """

    budget_s: float | None = None
    entries: dict[int, SiteLintEntry] = field(default_factory=dict)
    lock: threading.Lock = field(default_factory=threading.Lock)

    def entry(self, site_id: int, extent: Box, config: LintConfig) -> SiteLintEntry:
        """The site's entry; a new, empty one when there was none or the site extent or the config changed."""
        with self.lock:
            entry = self.entries.get(site_id)
            if entry is None or entry.extent != extent or entry.config != config:
                region = box(*extent)
                entry = SiteLintEntry(SiteLint(config=config, region=region, rank=int), extent, config)
                self.entries[site_id] = entry
            return entry

    def last_work(self, site_id: int) -> LintWork | None:
        """What the site's last catch-up linted (None before the first)."""
        with self.lock:
            entry = self.entries.get(site_id)
        return None if entry is None or entry.report is None else entry.work


def _lint_key(session: Session, site_id: int) -> LintKey:
    """A key that changes whenever any element of the site is created or changed (each change bumps a version)."""
    count, total = session.execute(
        select(func.count(), func.coalesce(func.sum(Element.version), 0)).where(Element.site_id == site_id)
    ).one()
    return int(count), int(total)


def _public_finding(finding: LintFinding) -> LintFindingPublic:
    """A finding with the database ids back as integers."""
    return LintFindingPublic(
        code=finding.code,
        severity=finding.severity,
        element_ids=[int(element_id) for element_id in finding.element_ids],
        location_xy=finding.location_xy,
        message=finding.message,
    )


def _in_bbox(xy: Sequence[float], bbox: Box) -> bool:
    """Whether a point lies in xmin, ymin, xmax, ymax."""
    return bbox[0] <= xy[0] <= bbox[2] and bbox[1] <= xy[1] <= bbox[3]


def _load(session: Session, element_ids: Sequence[int]) -> list[tuple[ElementView, int]]:
    """The live ones of these elements as views, with the version loaded."""
    query = select(Element.id, Element.version, Element.cls, Element.points).where(
        Element.id.in_(element_ids), Element.deleted.is_(False)
    )
    return [
        (ElementView(id=str(element_id), cls=cls, points=np.asarray(points, dtype=float)), version)
        for element_id, version, cls, points in session.execute(query.order_by(Element.id))
    ]


def _add_work(total: LintWork, work: LintWork) -> None:
    total.elements += work.elements
    total.pairs += work.pairs
    total.divider_ends += work.divider_ends


def _catch_up(
    session: Session, site_id: int, entry: SiteLintEntry, key: LintKey, budget_s: float | None
) -> LintReport:
    """Bring the entry to the database's state: lint the changed elements (loaded LOAD_CHUNK at a time) and
    what they can affect, until the budget runs out; its report, which counts the elements left pending."""
    started = time.monotonic()
    deadline = None if budget_s is None else started + budget_s
    query = select(Element.id, Element.version).where(Element.site_id == site_id, Element.deleted.is_(False))
    live = {element_id: version for element_id, version in session.execute(query)}
    changed = sorted(i for i, version in live.items() if entry.versions.get(i) != version)
    removed = [i for i in entry.versions if i not in live]
    entry.work = entry.state.update([], removed=[str(i) for i in removed])
    for element_id in removed:
        del entry.versions[element_id]
    linted = 0
    for start in range(0, len(changed), LOAD_CHUNK):
        if deadline is not None and linted and time.monotonic() >= deadline:
            break
        loaded = _load(session, changed[start : start + LOAD_CHUNK])
        work = entry.state.update([view for view, _version in loaded], deadline=deadline)
        _add_work(entry.work, work)
        pending = set(work.pending)
        entry.versions.update((int(view.id), version) for view, version in loaded if view.id not in pending)
        linted += len(loaded) - len(pending)
        if pending:
            break
    entry.work.pending = [str(i) for i in changed if entry.versions.get(i) != live[i]]
    findings = [_public_finding(finding) for finding in entry.state.findings()]
    entry.key = None if entry.work.pending else key
    entry.report = LintReport(
        site_id=site_id, element_count=len(live), findings=findings, pending_elements=len(entry.work.pending)
    )
    logger.info(
        "lint site %d: %d findings over %d elements in %.0f ms (linted %d elements, %d pairs, %d divider "
        "ends; %d pending)",
        site_id,
        len(findings),
        len(live),
        1000.0 * (time.monotonic() - started),
        entry.work.elements,
        entry.work.pairs,
        entry.work.divider_ends,
        len(entry.work.pending),
    )
    return entry.report


def _near(state: SiteLint, bbox: Box) -> int:
    """How many elements lie within reach of `bbox` (the ones its findings can involve)."""
    reach = max(state.reach_m, state.config.end_connect_m)
    return sum(
        view.bounds[2] >= bbox[0] - reach
        and view.bounds[0] <= bbox[2] + reach
        and view.bounds[3] >= bbox[1] - reach
        and view.bounds[1] <= bbox[3] + reach
        for view in state.views.values()
    )


def lint_site(
    *,
    session: Session,
    site_id: int,
    cache: LintCache,
    bbox: Box | None = None,
    config: LintConfig = LintConfig(),  # noqa: B008 - frozen, so a shared default is safe
) -> LintReport:
    """Lint the site's live elements (the site extent is the region where ends may stop).

    The cache keeps each site's lint up to date element by element: the first call lints the whole site, later
    ones only the elements changed since and what they can affect (`SiteLint.update`), and an unchanged site
    answers from the last report. A call lints for at most the cache's `budget_s` (then the report counts the
    elements left in `pending_elements`, and keeps their previous findings; the next call goes on). With
    `bbox`, only findings located inside it are returned, and the count of elements within reach of it.
    """
    site = get_site(session=session, site_id=site_id)
    extent = site_extent(site)
    entry = cache.entry(site_id, (extent.xmin, extent.ymin, extent.xmax, extent.ymax), config)
    with entry.lock:
        key = _lint_key(session, site_id)
        report = entry.report
        if entry.key != key or report is None:
            report = _catch_up(session, site_id, entry, key, cache.budget_s)
        if bbox is None:
            return report
        count = _near(entry.state, bbox)
    findings = [finding for finding in report.findings if _in_bbox(finding.location_xy, bbox)]
    return LintReport(
        site_id=site_id, element_count=count, findings=findings, pending_elements=report.pending_elements
    )


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
