"""Per-element reprojection figures (the paper's Algorithm 2 against the image lane masks, SRE at 960x540, the
share of images where the element matched) and the lead's worst-reprojection queue (issue 25).

Figures are cached per element version and camera inputs (`crud.reprojection`); a site without a reconstruction
answers null figures with the camera panel's notice.
"""

import logging
import threading
from typing import Annotated

from fastapi import APIRouter, Depends, Query, Request

from app.backend import crud
from app.backend.api.deps import CurrentUser, IdPath, SessionDep
from app.backend.api.routes.cameras import ContextDep
from app.backend.cameras.reprojection import InstanceCache
from app.backend.crud import reprojection
from app.backend.schemas_reprojection import ReprojectionPublic, ReprojectionQueuePage

logger = logging.getLogger(__name__)
router = APIRouter(prefix="/sites/{site_id}", tags=["reprojection"])
_STATE_LOCK = threading.Lock()


def get_instance_cache(request: Request) -> InstanceCache:
    """The app's cache of skeletonised lane instances, made on first use (one per app)."""
    with _STATE_LOCK:
        cache = getattr(request.app.state, "lane_instances", None)
        if cache is None:
            cache = request.app.state.lane_instances = InstanceCache()
    return cache


InstancesDep = Annotated[InstanceCache, Depends(get_instance_cache)]


@router.get("/elements/{element_id}/reprojection", response_model=ReprojectionPublic)
def read_reprojection(
    site_id: IdPath,
    element_id: IdPath,
    context: ContextDep,
    session: SessionDep,
    instances: InstancesDep,
    _user: CurrentUser,
) -> ReprojectionPublic:
    """The element's SRE at 960x540 and matched share over the images that see it (at most 12), cached until
    the element or the site's poses change; null figures with a notice when it cannot be scored."""
    element = crud.get_element(session=session, site_id=site_id, element_id=element_id)
    return reprojection.element_reprojection(
        session=session, element=element, context=context, instances=instances
    )


@router.get("/queues/reprojection", response_model=ReprojectionQueuePage)
def read_reprojection_queue(
    site_id: IdPath,
    context: ContextDep,
    session: SessionDep,
    instances: InstancesDep,
    _user: CurrentUser,
    limit: Annotated[int, Query(ge=1, le=1000)] = 50,
) -> ReprojectionQueuePage:
    """Dividers and boundaries worst first (matched in no image, then highest SRE); figures still missing are
    computed for up to 2 s per request and the rest reported as `pending`: ask again."""
    return reprojection.reprojection_queue(
        session=session,
        site_id=site_id,
        context=context,
        instances=instances,
        limit=limit,
        budget_s=reprojection.QUEUE_BUDGET_S,
    )
