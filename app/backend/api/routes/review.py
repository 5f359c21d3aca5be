"""Review transitions and history: move an element through review states, read its log, restore a version."""

import logging
from typing import Any

from fastapi import APIRouter, Request

from app.backend import crud
from app.backend.api.deps import CurrentUser, IdPath, SessionDep, SettingsDep, VersionPath
from app.backend.loop import CORRECTION_STATES, maybe_retrain
from app.backend.schemas import ConflictBody, EditLogPublic, ElementPublic, ReviewRequest, VersionRequest

logger = logging.getLogger(__name__)
router = APIRouter(prefix="/sites/{site_id}/elements/{element_id}", tags=["review"])
CONFLICT: dict[int | str, dict[str, Any]] = {
    403: {"description": "A lead's state or decision asked by an annotator."},
    409: {
        "model": ConflictBody,
        "description": "Stale version, invalid transition, or leased to another user.",
    },
}


@router.post("/review", response_model=ElementPublic, responses=CONFLICT)
def review(
    site_id: IdPath,
    element_id: IdPath,
    request: ReviewRequest,
    session: SessionDep,
    user: CurrentUser,
    settings: SettingsDep,
    http: Request,
) -> ElementPublic:
    """Annotators: proposed|returned -> accepted|fixed|rejected; leads also accepted|fixed -> approved|returned
    and approved -> returned (reopening approved work, which annotators may not change). Another user's unexpired lease on the element refuses the move with 409 naming the holder and expiry (leads
    override). Enough new accepted/fixed corrections start a retrain job (when the server is configured for it)."""
    element = crud.review_element(
        session=session,
        site_id=site_id,
        element_id=element_id,
        target=request.state,
        version=request.version,
        username=user.username,
        role=user.role,
    )
    view = crud.public(element)
    if request.state in CORRECTION_STATES:
        maybe_retrain(session=session, runner=http.app.state.jobs, settings=settings, site_id=site_id)
    return view


@router.get("/history", response_model=list[EditLogPublic])
def history(
    site_id: IdPath, element_id: IdPath, session: SessionDep, _user: CurrentUser
) -> list[EditLogPublic]:
    """The element's edit log, oldest first: who, when, action, before and after."""
    entries = crud.element_history(session=session, site_id=site_id, element_id=element_id)
    return [EditLogPublic.model_validate(entry) for entry in entries]


@router.post("/history/{restore_version}/restore", response_model=ElementPublic, responses=CONFLICT)
def restore(
    site_id: IdPath,
    element_id: IdPath,
    restore_version: VersionPath,
    request: VersionRequest,
    session: SessionDep,
    user: CurrentUser,
) -> ElementPublic:
    """Make an earlier version's content current again, as a new version (across a lead's approve/return:
    leads only, 403 otherwise; another user's lease: 409, leads override)."""
    element = crud.restore_version(
        session=session,
        site_id=site_id,
        element_id=element_id,
        restore=restore_version,
        version=request.version,
        username=user.username,
        role=user.role,
    )
    return crud.public(element)
