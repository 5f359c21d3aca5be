"""Map elements of a site: create, bulk proposals, bounding-box query, changes since a cursor, read, update,
soft delete."""

import logging
import math
from typing import Annotated, Any

from fastapi import APIRouter, Query, Response, status

from annotations.schema import ElementClass, ReviewState
from app.backend import crud
from app.backend.api.deps import MAX_ID, CurrentUser, IdPath, LeadUser, SessionDep, SettingsDep
from app.backend.crud.elements import Preaccept
from app.backend.crud.limits import VertexLimits
from app.backend.errors import InvalidInputError
from app.backend.models import Element
from app.backend.schemas import (
    ConflictBody,
    ElementChangesPublic,
    ElementCreate,
    ElementPublic,
    ElementUpdate,
    ProposalBulk,
)

logger = logging.getLogger(__name__)
router = APIRouter(prefix="/sites/{site_id}/elements", tags=["elements"])
CONFLICT: dict[int | str, dict[str, Any]] = {
    403: {"description": "An annotator's change to approved work (only a lead may change it)."},
    409: {
        "model": ConflictBody,
        "description": "Stale version (the body holds the current element), or leased to another user.",
    },
}


def element_response(element: Element, status_code: int = status.HTTP_200_OK) -> Response:
    """The element as JSON, serialised once: a returned model would be validated a second time against the
    response model (in another worker-thread hop) before being serialised."""
    body = crud.public(element).model_dump_json(by_alias=True)
    return Response(body, status_code=status_code, media_type="application/json")


def parse_bbox(bbox: str | None) -> tuple[float, float, float, float] | None:
    """`xmin,ymin,xmax,ymax` in site metres; InvalidInputError naming `bbox` otherwise."""
    if bbox is None:
        return None
    try:
        values = tuple(float(part) for part in bbox.split(","))
    except ValueError:
        raise InvalidInputError("bbox", f"expected 4 numbers xmin,ymin,xmax,ymax, got {bbox!r}") from None
    if len(values) != 4 or not all(math.isfinite(v) for v in values):
        raise InvalidInputError("bbox", f"expected 4 finite numbers xmin,ymin,xmax,ymax, got {bbox!r}")
    if values[0] > values[2] or values[1] > values[3]:
        raise InvalidInputError("bbox", f"min must not exceed max, got {bbox!r}")
    return values[0], values[1], values[2], values[3]


@router.get("", response_model=list[ElementPublic])
def list_elements(
    site_id: IdPath,
    session: SessionDep,
    _user: CurrentUser,
    bbox: Annotated[str | None, Query(description="xmin,ymin,xmax,ymax in site metres.")] = None,
    cls: Annotated[ElementClass | None, Query(alias="class")] = None,
    state: ReviewState | None = None,
    include_deleted: bool = False,
    limit: Annotated[int, Query(ge=1, le=100_000)] = 10_000,
) -> list[ElementPublic]:
    """Elements whose bounding box meets `bbox`, optionally filtered by class and state."""
    elements = crud.query_elements(
        session=session,
        site_id=site_id,
        bbox=parse_bbox(bbox),
        cls=cls,
        state=state,
        include_deleted=include_deleted,
        limit=limit,
    )
    return [crud.public(element) for element in elements]


@router.get("/changes", response_model=ElementChangesPublic)
def element_changes(
    site_id: IdPath,
    session: SessionDep,
    _user: CurrentUser,
    since: Annotated[
        int, Query(ge=0, le=MAX_ID, description="The previous answer's `cursor`; 0: every element.")
    ] = 0,
) -> ElementChangesPublic:
    """Elements created or changed after the cursor `since` (an edit-log id), deleted ones as ids, and the
    cursor to send next: read everything once with `since=0`, then poll; an idle poll carries no element. A
    cursor newer than the log (another database) is answered with cursor 0: read everything again."""
    changes = crud.element_changes(session=session, site_id=site_id, since=since)
    return ElementChangesPublic(
        cursor=changes.cursor,
        elements=[crud.public(element) for element in changes.elements],
        deleted=changes.deleted,
    )


@router.post("", response_model=ElementPublic, status_code=status.HTTP_201_CREATED)
def create_element(
    site_id: IdPath, element_in: ElementCreate, session: SessionDep, settings: SettingsDep, user: CurrentUser
) -> Response:
    """Draw a new element (version 1, state `proposed`)."""
    (element,) = crud.create_elements(
        session=session,
        site_id=site_id,
        elements_in=[element_in],
        username=user.username,
        margin_m=settings.extent_margin_m,
        limits=VertexLimits.of(settings),
    )
    return element_response(element, status.HTTP_201_CREATED)


@router.post("/bulk", response_model=list[ElementPublic], status_code=status.HTTP_201_CREATED)
def bulk_proposals(
    site_id: IdPath, bulk: ProposalBulk, session: SessionDep, settings: SettingsDep, user: LeadUser
) -> list[ElementPublic]:
    """Load many proposals at once (leads and admins); all are stored or none. With a configured
    CAMA_PREACCEPT_THRESHOLD, proposals at or above it enter pre-accepted (a CAMA_QA_SHARE of them to QA)."""
    preaccept = None
    if settings.preaccept_threshold is not None:
        preaccept = Preaccept(settings.preaccept_threshold, settings.qa_share, seed=len(bulk.elements))
    elements = crud.create_elements(
        session=session,
        site_id=site_id,
        elements_in=bulk.elements,
        username=user.username,
        margin_m=settings.extent_margin_m,
        preaccept=preaccept,
        limits=VertexLimits.of(settings),
    )
    return [crud.public(element) for element in elements]


@router.get("/{element_id}", response_model=ElementPublic)
def read_element(site_id: IdPath, element_id: IdPath, session: SessionDep, _user: CurrentUser) -> Response:
    """One element's current version (deleted ones too, flagged)."""
    return element_response(crud.get_element(session=session, site_id=site_id, element_id=element_id))


@router.patch("/{element_id}", response_model=ElementPublic, responses=CONFLICT)
def update_element(
    site_id: IdPath,
    element_id: IdPath,
    update: ElementUpdate,
    session: SessionDep,
    settings: SettingsDep,
    user: CurrentUser,
) -> Response:
    """Change class, points or confidence; the review state is kept. 409 with the current element when
    `version` is stale; 409 naming the holder and expiry when another user's lease holds the element (leads
    override); 403 for an annotator's change to an approved element: approval is a lead's final decision, so
    the edit is refused rather than reopening the element (a lead returns it first)."""
    element = crud.update_element(
        session=session,
        site_id=site_id,
        element_id=element_id,
        update=update,
        username=user.username,
        role=user.role,
        margin_m=settings.extent_margin_m,
        limits=VertexLimits.of(settings),
    )
    return element_response(element)


@router.delete("/{element_id}", response_model=ElementPublic, responses=CONFLICT)
def delete_element(
    site_id: IdPath,
    element_id: IdPath,
    version: Annotated[int, Query(ge=1, le=MAX_ID, description="The version last read.")],
    session: SessionDep,
    user: CurrentUser,
) -> Response:
    """Soft delete (kept and logged; restore an earlier version to undo). The same rules as `PATCH`: 409 for a
    stale version or another user's lease, 403 for an annotator's delete of an approved element."""
    element = crud.delete_element(
        session=session,
        site_id=site_id,
        element_id=element_id,
        version=version,
        username=user.username,
        role=user.role,
    )
    return element_response(element)
