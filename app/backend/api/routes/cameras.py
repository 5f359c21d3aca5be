"""The camera panel: whether a site has posed images, the views that see an element or a point, the images
and their lane-mask overlays (scaled, cached, immutable), the camera parameters and an element's projection.

Image files come only from the site's data set tables (`app.backend.cameras.image_file`), never from the
request; a token is `[0-9A-Za-z_-]{1,128}` (422 otherwise), one that is not a camera image of the data set, or
whose file resolves outside the data set root, is a 404. Answers name no server path.
"""

import logging
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path as FilePath
from typing import Annotated

import numpy as np
from fastapi import APIRouter, Depends, Path, Query, Request
from fastapi.responses import Response

from app.backend import crud
from app.backend.api.deps import CurrentUser, IdPath, SessionDep, SettingsDep
from app.backend.cameras import (
    NO_LANE_MASK,
    TOKEN_PATTERN,
    WIDTHS,
    CameraContext,
    ContextCache,
    ImageCache,
    ImageNotFound,
    cam_from_site,
    image_camera,
    image_file,
    lane_mask_file,
    lift_site_point,
    lift_site_points,
    project_neighbours,
    project_site_polyline,
    select,
)
from app.backend.cameras.views import ViewChoice
from app.backend.crud.cameras import element_neighbours, site_sources
from app.backend.errors import InvalidInputError, NotFoundError
from app.backend.schemas_cameras import (
    CameraPublic,
    CamerasStatus,
    NeighbourPublic,
    ProjectionPublic,
    ViewPublic,
    ViewsPublic,
)

logger = logging.getLogger(__name__)
router = APIRouter(prefix="/sites/{site_id}", tags=["cameras"])
_STATE_LOCK = threading.Lock()
IMAGE_CACHE_CONTROL = "private, max-age=31536000, immutable"
"""A data set image never changes under its token (a rewritten file gets a new ETag, and the browser keys its
cache on the URL, which holds the token and width); `private` because the answer needs a login, so no shared
cache may keep it."""
IMAGE: dict[int | str, dict[str, object]] = {
    200: {"content": {"image/jpeg": {}}, "description": "The camera image (JPEG)."},
    304: {"description": "Not modified (If-None-Match matched the ETag)."},
    404: {"description": "Not a camera image of the site's data set."},
}
MASK: dict[int | str, dict[str, object]] = {
    200: {"content": {"image/png": {}}, "description": "RGBA overlay: each lane instance its own colour."},
    304: {"description": "Not modified (If-None-Match matched the ETag)."},
    404: {"description": "Not a camera image of the site's data set, or no lane mask for it."},
}
Token = Annotated[str, Path(pattern=TOKEN_PATTERN, description="A camera image's sample_data token.")]
MAX_SITE_M = 100_000.0
"""A site point further than this from the site origin (metres) is refused (422): no site is that large, and
squaring such numbers overflows."""
Width = Annotated[int | None, Query(description="One of 240, 320, 480, 640, 960; omitted: full size.")]


@dataclass
class CameraState:
    """The app's camera contexts and encoded-image cache."""

    contexts: ContextCache = field(default_factory=ContextCache)
    images: ImageCache = field(default_factory=ImageCache)


def get_camera_state(request: Request) -> CameraState:
    """The app's camera state, made on first use (one per app: tests and servers never share one)."""
    with _STATE_LOCK:
        state = getattr(request.app.state, "cameras", None)
        if state is None:
            state = request.app.state.cameras = CameraState()
    return state


CameraStateDep = Annotated[CameraState, Depends(get_camera_state)]


def site_context(
    session: SessionDep, settings: SettingsDep, state: CameraStateDep, site_id: IdPath
) -> CameraContext:
    """The site's camera context (404 for an unknown site)."""
    site = crud.get_site(session=session, site_id=site_id)
    return state.contexts.get(site_sources(site, settings.allowed_data_roots))


ContextDep = Annotated[CameraContext, Depends(site_context)]


def check_width(width: int | None) -> None:
    """422 naming `width` unless it is one of WIDTHS (or omitted)."""
    if width is not None and width not in WIDTHS:
        raise InvalidInputError(
            "width", f"must be one of {', '.join(map(str, WIDTHS))}, or omitted for full size"
        )


def views_public(choices: list[ViewChoice]) -> list[ViewPublic]:
    """The API shape of view choices."""
    return [ViewPublic.model_validate(choice, from_attributes=True) for choice in choices]


def pixels(pieces: list[np.ndarray]) -> list[list[list[float]]]:
    """Pieces as JSON lists of [u, v], rounded to 0.01 px."""
    return [np.round(piece, 2).tolist() for piece in pieces]


@router.get("/cameras", response_model=CamerasStatus)
def read_cameras(context: ContextDep, _user: CurrentUser) -> CamerasStatus:
    """Whether the site has posed key-frame images, how many, where its lane masks come from, and a notice
    when the panel can show nothing."""
    return CamerasStatus(
        available=context.available,
        notice=context.notice,
        images=context.images,
        posed=len(context.views),
        mask_source=context.mask_source,  # type: ignore[arg-type]  # one of the literals or None
    )


@router.get("/views", response_model=ViewsPublic)
def read_views(
    site_id: IdPath,
    context: ContextDep,
    session: SessionDep,
    _user: CurrentUser,
    element_id: Annotated[int | None, Query(ge=1, description="The element to see.")] = None,
    x: Annotated[
        float | None, Query(ge=-MAX_SITE_M, le=MAX_SITE_M, description="Or a site point: x (metres).")
    ] = None,
    y: Annotated[float | None, Query(ge=-MAX_SITE_M, le=MAX_SITE_M, description="And y (metres).")] = None,
    n: Annotated[int, Query(ge=2, le=6, description="How many views (2..6).")] = 4,
    all_: Annotated[
        bool, Query(alias="all", description="Every view that sees it, in station order.")
    ] = False,
) -> ViewsPublic:
    """The n key-frame images that see the element (or point) best, spread along it, in station order."""
    if (element_id is None) == (x is None and y is None) or (x is None) != (y is None):
        raise InvalidInputError("element_id", "give element_id, or both x and y (site metres)")
    if element_id is not None:
        element = crud.get_element(session=session, site_id=site_id, element_id=element_id)
        lifted = lift_site_points(context, element.points)
    else:  # both set (checked above), finite and within MAX_SITE_M (the query's bounds)
        lifted = lift_site_point(context, (x, y))  # type: ignore[arg-type]
    if not context.available:
        return ViewsPublic(notice=context.notice, views=[])
    return ViewsPublic(notice=lifted.notice, views=views_public(select(context, lifted, n, all_)))


def _served(request: Request, state: CameraState, kind: str, path: FilePath, width: int | None) -> Response:
    """The encoded file with its ETag and immutable cache policy, or a 304 when the browser has it."""
    etag = state.images.etag(kind, path, width)
    headers = {"Cache-Control": IMAGE_CACHE_CONTROL, "ETag": etag}
    if request.headers.get("if-none-match") == etag:
        return Response(status_code=304, headers=headers)
    try:
        encoded = state.images.get(kind, path, width)
    except ValueError as error:
        logger.warning("%s not served: %s", kind, error)
        raise NotFoundError("the image's file cannot be read") from None
    return Response(encoded.data, media_type=encoded.media_type, headers=headers)


def _served_lookup(
    request: Request,
    state: CameraState,
    kind: str,
    width: int | None,
    find: Callable[[], FilePath],
) -> Response:
    """Check the width, find the file (404 naming why when there is none) and serve it (`_served`)."""
    check_width(width)
    try:
        path = find()
    except ImageNotFound as error:
        raise NotFoundError(str(error)) from None
    return _served(request, state, kind, path, width)


def _lane_mask(context: CameraContext, token: str) -> FilePath:
    """The image's lane instance mask file; NotFoundError when the image has none."""
    path = lane_mask_file(context, token)
    if path is None:
        raise NotFoundError(NO_LANE_MASK)
    return path


@router.get("/images/{token}", response_class=Response, response_model=None, responses=IMAGE)
def read_image(
    token: Token,
    request: Request,
    context: ContextDep,
    state: CameraStateDep,
    _user: CurrentUser,
    width: Width = None,
) -> Response:
    """A camera image of the site's data set, scaled to `width` (INTER_AREA), JPEG, cached for a year."""
    return _served_lookup(request, state, "image", width, lambda: image_file(context, token))


@router.get("/images/{token}/lane-mask", response_class=Response, response_model=None, responses=MASK)
def read_lane_mask(
    token: Token,
    request: Request,
    context: ContextDep,
    state: CameraStateDep,
    _user: CurrentUser,
    width: Width = None,
) -> Response:
    """The image's lane instances as an RGBA overlay (data set's masks, else predicted or imported ones)."""
    return _served_lookup(request, state, "lane-mask", width, lambda: _lane_mask(context, token))


@router.get("/images/{token}/camera", response_model=CameraPublic)
def read_camera(token: Token, context: ContextDep, _user: CurrentUser) -> CameraPublic:
    """The image's intrinsics and its pose as a map from site coordinates into the camera frame."""
    try:
        found = image_camera(context, token)
    except ImageNotFound as error:
        raise NotFoundError(str(error)) from None
    camera = found.camera
    return CameraPublic(
        width=camera.width,
        height=camera.height,
        K=camera.intrinsic.tolist(),
        cam_from_site=cam_from_site(camera, context.site_origin_xy).tolist(),
        pose_source=found.pose_source,
    )


@router.get("/elements/{element_id}/projection", response_model=ProjectionPublic)
def read_projection(
    site_id: IdPath,
    element_id: IdPath,
    context: ContextDep,
    session: SessionDep,
    _user: CurrentUser,
    image: Annotated[str, Query(pattern=TOKEN_PATTERN, description="The image's token.")],
    neighbours: Annotated[bool, Query(description="Also project the live elements within 30 m.")] = False,
) -> ProjectionPublic:
    """The element lifted through the elevation raster and projected into the image (its visible pieces), and
    optionally its neighbours."""
    element = crud.get_element(session=session, site_id=site_id, element_id=element_id)
    try:
        camera = image_camera(context, image).camera
    except ImageNotFound as error:
        raise NotFoundError(str(error)) from None
    lifted = lift_site_points(context, element.points)
    near = element_neighbours(session=session, element=element) if neighbours else []
    return ProjectionPublic(
        points_3d=[[round(v, 3) for v in point] for point in lifted.points_3d.tolist()],
        pieces=pixels(project_site_polyline(context, camera, lifted.points_3d)),
        neighbours=[
            NeighbourPublic(id=item.id, cls=item.cls, pieces=pixels(item.pieces))
            for item in project_neighbours(context, camera, near)
        ],
        notice=lifted.notice,
    )
