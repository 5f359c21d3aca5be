"""API shapes of the per-element reprojection figures and the lead's worst-reprojection queue (issue 25)."""

import logging
from datetime import datetime

from pydantic import BaseModel, ConfigDict, Field

from annotations.schema import ElementClass, ReviewState

logger = logging.getLogger(__name__)


class ReprojectionPublic(BaseModel):
    """One element's agreement with the camera images' lane masks (the paper's Algorithm 2)."""

    element_id: int
    element_version: int = Field(description="The element version the figures are for.")
    sre_px: float | None = Field(
        description="Semantic reprojection error at 960x540 over the images where it matched; null when it "
        "matched in none (or was not scored)."
    )
    matched_share: float | None = Field(
        description="Share of the scored images (those that see it, at most 12) where it matched a lane "
        "instance of its class; null when no image scored it."
    )
    images: int = Field(description="Images that scored the element.")
    computed_at: datetime | None = Field(description="When the figures were computed; null when not scored.")
    notice: str | None = Field(
        default=None, description="Why there are no figures (no reconstruction, a crosswalk, no lane masks)."
    )


class ReprojectionQueueItem(ReprojectionPublic):
    """An element of the worst-reprojection queue."""

    model_config = ConfigDict(populate_by_name=True, serialize_by_alias=True)
    id: int
    cls: ElementClass = Field(serialization_alias="class")
    state: ReviewState


class ReprojectionQueuePage(BaseModel):
    """The site's scored elements, worst first: unmatched (seen, matched nowhere), then by SRE, highest first."""

    items: list[ReprojectionQueueItem]
    total: int = Field(description="Scored elements seen by at least one image (the ranked ones).")
    pending: int = Field(description="Elements whose figures are still to be computed (ask again).")
    unseen: int = Field(description="Elements no posed image sees (not ranked).")
    notice: str | None = Field(default=None, description="Why nothing can be scored, when so.")
