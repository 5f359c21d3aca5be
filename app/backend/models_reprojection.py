"""ORM model of the per-element reprojection figures' cache (issue 25): one row per element, valid while the
element's version and the site's camera inputs are those it was computed for.

It shares `models.Base`, so Alembic's target metadata sees it once this module is imported (the migration
environment imports it).
"""

import logging
from datetime import datetime

from sqlalchemy import Float, ForeignKey, Integer, String, Text
from sqlalchemy.orm import Mapped, mapped_column

from app.backend.models import Base, UtcDateTime

logger = logging.getLogger(__name__)


class ElementReprojection(Base):
    """An element's SRE against the image lane masks and its matched share, as last computed.

    The row is looked up by (element id, element version, inputs digest): an edit bumps the version, a new
    reconstruction (poses), elevation raster or mask source changes the digest, and either makes the row stale;
    the next request recomputes it and overwrites the row, so there is never more than one per element.
    """

    __tablename__ = "element_reprojection"

    element_id: Mapped[int] = mapped_column(ForeignKey("elements.id", ondelete="CASCADE"), primary_key=True)
    element_version: Mapped[int] = mapped_column(Integer)
    inputs_digest: Mapped[str] = mapped_column(String(64))
    """`app.backend.cameras.reprojection.inputs_digest`: the posed views' poses, the elevation, the mask source."""
    sre_px: Mapped[float | None] = mapped_column(Float, nullable=True)
    """SRE at 960x540; NULL when no image matched the element."""
    matched_share: Mapped[float | None] = mapped_column(Float, nullable=True)
    """Share of the scored images where the element matched a lane instance; NULL when none was scored."""
    images: Mapped[int] = mapped_column(Integer)
    """Images that scored the element."""
    notice: Mapped[str | None] = mapped_column(Text, nullable=True)
    computed_at: Mapped[datetime] = mapped_column(UtcDateTime())
