"""Vertex limits of element writes: per element and per site (the lint's first build and the memory its cache
holds grow with a site's vertices), checked on create, bulk create and update."""

from collections.abc import Sequence
from dataclasses import dataclass

from sqlalchemy import func, select
from sqlalchemy.orm import Session

from app.backend.config import Settings
from app.backend.errors import InvalidInputError
from app.backend.models import Element


@dataclass(frozen=True)
class VertexLimits:
    """Most vertices of one element and of one site's live elements together."""

    per_element: int
    per_site: int

    @classmethod
    def of(cls, settings: Settings) -> "VertexLimits":
        """The limits the settings give (`CAMA_MAX_ELEMENT_VERTICES`, `CAMA_MAX_SITE_VERTICES`)."""
        return cls(per_element=settings.max_element_vertices, per_site=settings.max_site_vertices)


def site_vertex_count(session: Session, site_id: int) -> int:
    """Vertices of the site's live elements (the database counts the JSON arrays)."""
    query = select(func.coalesce(func.sum(func.json_array_length(Element.points)), 0)).where(
        Element.site_id == site_id, Element.deleted.is_(False)
    )
    return int(session.execute(query).scalar_one())


def check_vertex_limits(
    *,
    session: Session,
    site_id: int,
    limits: VertexLimits,
    counts: Sequence[int],
    fields: Sequence[str],
    replaced: int = 0,
) -> None:
    """InvalidInputError (422) naming the limit when an element has more than `per_element` vertices, or when the
    site would hold more than `per_site` once elements of `counts` vertices are written in place of `replaced`
    vertices (the site is counted only when the write adds vertices)."""
    for count, field in zip(counts, fields, strict=True):
        if count > limits.per_element:
            raise InvalidInputError(
                field,
                f"{count} vertices, over the limit of {limits.per_element} per element "
                "(CAMA_MAX_ELEMENT_VERTICES); split the element or simplify it",
            )
    added = sum(counts) - replaced
    if added <= 0:
        return
    stored = site_vertex_count(session, site_id)
    if stored + added > limits.per_site:
        raise InvalidInputError(
            fields[0] if len(fields) == 1 else "elements",
            f"site {site_id} holds {stored} vertices; {added} more would pass the limit of {limits.per_site} "
            "per site (CAMA_MAX_SITE_VERTICES)",
        )
