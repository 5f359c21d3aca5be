"""API request and response shapes (pydantic), separate from the ORM models.

Element geometry is validated by the `annotations` package (`MapElement`): one definition of a valid element.
Non-finite numbers are rejected at parse time (`allow_inf_nan=False`), since JSON parsers accept NaN. Request
shapes are strict (`STRICT`): no string or boolean is taken for a number (`"1"`, `true`, `[false, 0]` are 422);
an integer is a number wherever a float is expected, since JSON does not tell `1` from `1.0`.
"""

import logging
from collections.abc import Sequence
from datetime import datetime
from typing import Annotated, Any, Literal, Self

from pydantic import AliasChoices, BaseModel, ConfigDict, Field, ValidationError, model_validator

from annotations.schema import ElementClass, MapElement, ReviewState, Source
from cama_pipeline.bev import RasterGeoreference

logger = logging.getLogger(__name__)

Role = Literal["annotator", "lead", "admin"]
Point = Annotated[Sequence[float], Field(min_length=2, max_length=2)]
"""[x, y] in metres (an array of two numbers; a plain array keeps the OpenAPI schema simple for clients)."""
STRICT = ConfigDict(strict=True, extra="forbid", allow_inf_nan=False, populate_by_name=True)
"""For request shapes: unknown fields, non-finite numbers and type coercions (strings or booleans as numbers)
are refused."""
MAX_ID = 2**63 - 1
"""Largest value a database integer column holds (signed 64 bits)."""
DbId = Annotated[int, Field(ge=1, le=MAX_ID)]
"""An id or version sent in a request body: larger ones get 422 before any query (SQLite would overflow)."""


def check_element(*, cls: str, points: Sequence[Point], source: str, confidence: float | None) -> None:
    """Validate an element through `annotations.MapElement`; ValueError naming the field on failure."""
    try:
        MapElement.model_validate(
            {"id": "new", "class": cls, "points_2d": points, "source": source, "confidence": confidence}
        )
    except ValidationError as error:
        messages = []
        for item in error.errors():
            field = ".".join(str(part) for part in item["loc"]) or "element"
            field = "points" if field.startswith("points_2d") else field
            message = str(item["msg"]).removeprefix("Value error, ")
            messages.append(
                message.replace("points_2d", "points") if ":" in message else f"{field}: {message}"
            )
        raise ValueError("; ".join(messages)) from None


class LoginRequest(BaseModel):
    """Credentials for `POST /api/auth/login` (JSON or form-encoded)."""

    model_config = STRICT
    username: str = Field(min_length=1, max_length=64)
    password: str = Field(min_length=1, max_length=1024)


class TokenPublic(BaseModel):
    """A bearer token and when it expires."""

    access_token: str
    token_type: Literal["bearer"] = "bearer"
    expires_at: datetime


class UserCreate(BaseModel):
    """A new user, made by an admin."""

    model_config = STRICT
    username: str = Field(min_length=1, max_length=64, pattern=r"^[A-Za-z0-9_.@-]+$")
    password: str = Field(min_length=8, max_length=1024)
    role: Role = "annotator"


class UserPublic(BaseModel):
    """A user as the API shows it (never the password hash)."""

    model_config = ConfigDict(from_attributes=True)
    id: int
    username: str
    role: Role
    is_active: bool


class GeoreferenceIn(BaseModel):
    """A raster georeference (`cama_pipeline.bev.RasterGeoreference`, DESIGN.md convention) in a request."""

    model_config = STRICT
    origin_xy: Point
    resolution: float = Field(gt=0.0)
    width: int = Field(ge=1)
    height: int = Field(ge=1)

    @classmethod
    def of(cls, raster: RasterGeoreference) -> Self:
        """The request field for a raster folder's georeference."""
        return cls.model_validate(raster.model_dump(include=set(cls.model_fields)))

    def raster(self) -> RasterGeoreference:
        """The georeference this request gives."""
        return RasterGeoreference.model_validate(self.model_dump())


class SiteCreate(BaseModel):
    """Register a site from a synthetic site folder, or from a georeference plus a raster folder."""

    model_config = STRICT
    name: str = Field(min_length=1, max_length=128)
    synthetic_dir: str | None = Field(default=None, description="Folder written by `cama synth`.")
    site_origin_xy: Point | None = None
    georeference: GeoreferenceIn | None = None
    raster_dir: str | None = None
    dataset_root: str | None = Field(
        default=None,
        description="The nuScenes-layout data set of the camera images (default: `synthetic_dir/nuscenes`, or "
        "`nuscenes` beside a workspace named `workspace`).",
    )
    workspace_dir: str | None = Field(
        default=None,
        description="The pipeline workspace whose SfM poses pose the camera images (default: the workspace of a "
        "surface stage's raster_dir, or `synthetic_dir/workspace`).",
    )

    @model_validator(mode="after")
    def _one_source(self) -> Self:
        """Either `synthetic_dir` or all of `site_origin_xy`, `georeference`, `raster_dir`."""
        manual = (self.site_origin_xy, self.georeference, self.raster_dir)
        if self.synthetic_dir is None and any(value is None for value in manual):
            raise ValueError("give synthetic_dir, or site_origin_xy + georeference + raster_dir")
        if self.synthetic_dir is not None and any(value is not None for value in manual):
            raise ValueError("synthetic_dir: give it alone, not with site_origin_xy/georeference/raster_dir")
        return self


class Extent(BaseModel):
    """An axis-aligned box in site metres."""

    xmin: float
    ymin: float
    xmax: float
    ymax: float


class SitePublic(BaseModel):
    """A site in lists."""

    id: int
    name: str
    site_origin_xy: Point
    extent: Extent


class SiteDetail(SitePublic):
    """A site with its georeference, raster layers and element counts."""

    georeference: dict[str, Any]
    layers: list[str]
    element_count: int
    counts_by_state: dict[str, int]
    counts_by_class: dict[str, int]


class ElementCreate(BaseModel):
    """A new element; geometry checked by `annotations.MapElement`."""

    model_config = STRICT
    cls: ElementClass = Field(validation_alias=AliasChoices("class", "cls"), serialization_alias="class")
    points: list[Point] = Field(
        description="[x, y] site metres; crosswalks closed; at most CAMA_MAX_ELEMENT_VERTICES (10,000) points."
    )
    confidence: float | None = Field(default=None, ge=0.0, le=1.0)
    source: Source = "human"
    model: str | None = Field(
        default=None,
        min_length=1,
        max_length=64,
        description="The proposer that made a proposal (e.g. `vma-v0003`, `rule-based`); only with source proposal.",
    )

    @model_validator(mode="after")
    def _valid_geometry(self) -> Self:
        """Reject < 2 points, coincident points, open or self-crossing crosswalks, proposals without confidence,
        and a model named for an element a person drew."""
        check_element(cls=self.cls, points=self.points, source=self.source, confidence=self.confidence)
        if self.model is not None and self.source != "proposal":
            raise ValueError("model: only a proposal names the model that made it (source is not 'proposal')")
        return self


class ProposalBulk(BaseModel):
    """Many proposals at once; all are stored or none."""

    model_config = STRICT
    elements: list[ElementCreate] = Field(min_length=1, max_length=50_000)


class ElementUpdate(BaseModel):
    """A change to an element; `version` must be the one last read (optimistic concurrency)."""

    model_config = STRICT
    version: DbId
    cls: ElementClass | None = Field(
        default=None, validation_alias=AliasChoices("class", "cls"), serialization_alias="class"
    )
    points: list[Point] | None = Field(
        default=None, description="At most CAMA_MAX_ELEMENT_VERTICES (10,000) points."
    )
    confidence: float | None = Field(default=None, ge=0.0, le=1.0)


class ElementPublic(BaseModel):
    """An element's current version."""

    model_config = ConfigDict(populate_by_name=True, serialize_by_alias=True)
    id: int
    site_id: int
    cls: ElementClass = Field(serialization_alias="class", validation_alias=AliasChoices("class", "cls"))
    points: list[Point]
    confidence: float | None
    source: Source
    state: ReviewState
    deleted: bool
    version: int
    author: str | None
    created_at: datetime
    updated_at: datetime
    proposed_by: str | None = Field(
        default=None,
        description="The model that proposed this element (its first version), when it was a proposal that named it.",
    )
    preaccepted: bool = Field(
        default=False,
        description="Entered as accepted by the model (confidence above the calibrated threshold).",
    )
    qa_sample: bool = Field(
        default=False, description="A pre-accepted element sampled for the lead's QA queue."
    )


class ElementChangesPublic(BaseModel):
    """A site's element changes after a cursor: poll with `since` set to the last answer's `cursor`."""

    cursor: int = Field(description="The newest edit-log id this answer covers: the next `since`.")
    elements: list[ElementPublic] = Field(
        description="Elements created or changed since, at their current version (deleted ones excluded)."
    )
    deleted: list[int] = Field(description="Ids of elements deleted since.")


class ReviewRequest(BaseModel):
    """Move an element to a review state; `version` as last read."""

    model_config = STRICT
    state: Literal["accepted", "fixed", "rejected", "approved", "returned"]
    version: DbId


class VersionRequest(BaseModel):
    """Carries the version last read, for changes without other content (restore)."""

    model_config = STRICT
    version: DbId


class EditLogPublic(BaseModel):
    """One entry of an element's edit log."""

    model_config = ConfigDict(from_attributes=True)
    id: int
    element_id: int
    version: int
    username: str
    at: datetime
    action: str
    before: dict[str, Any] | None
    after: dict[str, Any]


class ConflictBody(BaseModel):
    """The 409 body: why, and the element as stored now."""

    detail: str
    current: ElementPublic | None = None
