"""Map quality: lint on demand and after a save, proposal-to-final diffs, and annotator figures (leads)."""

import logging

from fastapi import APIRouter

from app.backend.api.deps import CurrentUser, IdPath, LeadUser, LintCacheDep, SessionDep
from app.backend.crud import quality
from app.backend.errors import InvalidInputError
from app.backend.schemas_quality import (
    AnnotatorFiguresPublic,
    ClassDiffSummary,
    LintFindingPublic,
    LintReport,
    LintRequest,
    ProposalDiffPublic,
)

logger = logging.getLogger(__name__)
router = APIRouter(prefix="/sites/{site_id}", tags=["quality"])


@router.get("/lint", response_model=LintReport)
def read_lint(site_id: IdPath, session: SessionDep, cache: LintCacheDep, _user: CurrentUser) -> LintReport:
    """The findings over the whole site; recomputed only when an element changed since the last run."""
    return quality.lint_site(session=session, site_id=site_id, cache=cache)


@router.post("/lint", response_model=LintReport)
def run_lint(
    site_id: IdPath, request: LintRequest, session: SessionDep, cache: LintCacheDep, _user: CurrentUser
) -> LintReport:
    """Lint on demand; with `bbox`, only findings located inside it."""
    bbox = request.bbox
    if bbox is not None and (bbox[0] > bbox[2] or bbox[1] > bbox[3]):
        raise InvalidInputError("bbox", f"min must not exceed max, got {list(bbox)}")
    return quality.lint_site(session=session, site_id=site_id, cache=cache, bbox=bbox)


@router.get("/elements/{element_id}/lint", response_model=list[LintFindingPublic])
def read_element_lint(
    site_id: IdPath, element_id: IdPath, session: SessionDep, cache: LintCacheDep, _user: CurrentUser
) -> list[LintFindingPublic]:
    """Findings involving this element (call after a save to show what the edit broke or fixed)."""
    return quality.element_findings(session=session, site_id=site_id, element_id=element_id, cache=cache)


@router.get("/elements/{element_id}/diff", response_model=ProposalDiffPublic)
def read_element_diff(
    site_id: IdPath, element_id: IdPath, session: SessionDep, _user: CurrentUser
) -> ProposalDiffPublic:
    """The element's current geometry and class against its proposal; 404 for an element drawn by hand."""
    return quality.element_diff(session=session, site_id=site_id, element_id=element_id)


@router.get("/diffs", response_model=list[ClassDiffSummary])
def read_diff_summary(site_id: IdPath, session: SessionDep, _user: CurrentUser) -> list[ClassDiffSummary]:
    """Per proposal class over reviewed proposals: unchanged count, mean Chamfer, vertices moved/added/removed."""
    return quality.diff_summary(session=session, site_id=site_id)


@router.get("/figures", response_model=list[AnnotatorFiguresPublic])
def read_figures(site_id: IdPath, session: SessionDep, _lead: LeadUser) -> list[AnnotatorFiguresPublic]:
    """Per annotator and class: items per hour, proposals accepted unchanged, displacement of fixes (leads)."""
    rows = quality.site_figures(session=session, site_id=site_id)
    return [AnnotatorFiguresPublic.model_validate(row) for row in rows]
