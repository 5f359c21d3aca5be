"""Sites: register (admin or lead), list and describe (any user)."""

import logging

from fastapi import APIRouter, status

from app.backend import crud
from app.backend.api.deps import CurrentUser, IdPath, LeadUser, SessionDep, SettingsDep
from app.backend.models import Site
from app.backend.schemas import SiteCreate, SiteDetail, SitePublic

logger = logging.getLogger(__name__)
router = APIRouter(prefix="/sites", tags=["sites"])


def _public(site: Site) -> SitePublic:
    """The list view of a site."""
    return SitePublic(
        id=site.id,
        name=site.name,
        site_origin_xy=(site.site_origin_x, site.site_origin_y),
        extent=crud.site_extent(site),
    )


@router.post("", response_model=SiteDetail, status_code=status.HTTP_201_CREATED)
def create_site(
    site_in: SiteCreate, session: SessionDep, settings: SettingsDep, _lead: LeadUser
) -> SiteDetail:
    """Register a site from a `cama synth` folder or from a georeference and a raster folder; the folder must
    lie inside the server's data roots (CAMA_DATA_ROOTS)."""
    site = crud.create_site(session=session, site_in=site_in, roots=settings.allowed_data_roots)
    return read_site(site.id, session, _lead)


@router.get("", response_model=list[SitePublic])
def list_sites(session: SessionDep, _user: CurrentUser) -> list[SitePublic]:
    """All sites."""
    return [_public(site) for site in crud.list_sites(session=session)]


@router.get("/{site_id}", response_model=SiteDetail)
def read_site(site_id: IdPath, session: SessionDep, _user: CurrentUser) -> SiteDetail:
    """A site's extent, georeference, raster layers present and element counts by state and class."""
    site = crud.get_site(session=session, site_id=site_id)
    by_state, by_class = crud.site_counts(session=session, site_id=site_id)
    return SiteDetail(
        **_public(site).model_dump(),
        georeference=site.georeference,
        layers=crud.site_layers(site),
        element_count=sum(by_state.values()),
        counts_by_state=by_state,
        counts_by_class=by_class,
    )
