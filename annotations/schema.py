"""The vector annotation model: map elements, the site georeference and a site's annotation set (pydantic v2).

Coordinates are site metres (global - site_origin_xy); a `ped_crossing` is a closed polygon ring (first point ==
last point), the other classes are open polylines. JSON uses the key "class" for `MapElement.cls`.
"""

import logging
from collections.abc import Iterable
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, Literal, Self

import numpy as np
from pydantic import (
    AliasChoices,
    BaseModel,
    ConfigDict,
    Field,
    SerializerFunctionWrapHandler,
    ValidationError,
    ValidationInfo,
    field_validator,
    model_serializer,
    model_validator,
)

from annotations.geometry import validate_geometry
from cama_pipeline.bev import RasterGeoreference
from cama_pipeline.io import atomic_write_bytes

logger = logging.getLogger(__name__)

ElementClass = Literal["divider", "ped_crossing", "boundary"]
ELEMENT_CLASSES: tuple[ElementClass, ...] = ("divider", "ped_crossing", "boundary")
POLYGON_CLASSES: frozenset[str] = frozenset({"ped_crossing"})
"""Classes stored as closed polygon rings rather than open polylines."""

Source = Literal["proposal", "human"]
ReviewState = Literal["proposed", "accepted", "fixed", "rejected", "approved", "returned"]

ANNOTATION_FORMAT_VERSION: Literal[1] = 1


def utc_now() -> datetime:
    """The current time, timezone-aware in UTC."""
    return datetime.now(UTC)


class MapElement(BaseModel):
    """One map vector (divider, road boundary or crosswalk polygon) with its provenance and review state.

    Frozen: change it with `with_changes`, which validates; never mutate the point lists in place.
    """

    model_config = ConfigDict(
        frozen=True, extra="forbid", validate_by_name=True, validate_by_alias=True, serialize_by_alias=True
    )

    id: str = Field(min_length=1, description="Stable element id, unique within a site.")
    cls: ElementClass = Field(
        validation_alias=AliasChoices("class", "cls"),
        serialization_alias="class",
        description='Vector class, as in MapTR / VMA; the JSON key is "class".',
    )
    points_2d: list[tuple[float, float]] = Field(description="[x, y] site metres; polygons closed.")
    points_3d: list[tuple[float, float, float]] | None = Field(
        default=None, description="[x, y, z] site metres (z global), e.g. from the elevation lift."
    )
    source: Source = Field(description="Who drew it: a model proposal or a person.")
    confidence: float | None = Field(
        default=None, ge=0.0, le=1.0, description="Model confidence in [0, 1]; required for proposals."
    )
    review_state: ReviewState = Field(default="proposed", description="Where the element is in review.")
    version: int = Field(default=1, ge=1, description="Edit version, starting at 1.")
    author: str | None = Field(default=None, description="User or model that made this version.")
    created_at: datetime = Field(default_factory=utc_now, description="Creation time (UTC).")
    updated_at: datetime = Field(default_factory=utc_now, description="Time of this version (UTC).")

    @field_validator("points_2d", "points_3d")
    @classmethod
    def _check_points(cls, value: list[tuple[float, ...]] | None, info: ValidationInfo) -> Any:
        """Validate the geometry: >= 2 finite points; crosswalk polygons closed and simple."""
        if value is None:
            return value
        element_class = info.data.get("cls")  # absent when the class itself failed validation
        dims = 2 if info.field_name == "points_2d" else 3
        validate_geometry(
            value, closed=element_class in POLYGON_CLASSES, field=info.field_name or "points", dims=dims
        )
        return value

    @field_validator("created_at", "updated_at")
    @classmethod
    def _to_utc(cls, value: datetime) -> datetime:
        """Store times in UTC; a naive time is taken to be UTC already."""
        return value.replace(tzinfo=UTC) if value.tzinfo is None else value.astimezone(UTC)

    @model_validator(mode="after")
    def _check_provenance(self) -> Self:
        """A proposal carries a confidence; a version cannot predate its element."""
        if self.source == "proposal" and self.confidence is None:
            raise ValueError("confidence: required when source is 'proposal'")
        if self.updated_at < self.created_at:
            raise ValueError(f"updated_at: {self.updated_at.isoformat()} is before created_at")
        return self

    @property
    def closed(self) -> bool:
        """Whether this element is a polygon ring (crosswalk) rather than an open polyline."""
        return self.cls in POLYGON_CLASSES

    def xy(self) -> np.ndarray:
        """The 2D points as a float (N, 2) array."""
        return np.asarray(self.points_2d, dtype=float)

    def xyz(self) -> np.ndarray | None:
        """The 3D points as a float (N, 3) array, or None when not lifted."""
        return None if self.points_3d is None else np.asarray(self.points_3d, dtype=float)

    def with_changes(self, **changes: Any) -> "MapElement":
        """A validated copy with some fields replaced (model_copy would skip validation)."""
        return MapElement.model_validate({**self.model_dump(by_alias=False), **changes})


def _site_origin_first_in_schema(schema: dict[str, Any]) -> None:
    """`required` lists site_origin_xy first, as the annotation formats always have."""
    schema["required"] = [
        "site_origin_xy",
        *(name for name in schema["required"] if name != "site_origin_xy"),
    ]


class Georeference(RasterGeoreference):
    """Where a site and its BEV rasters sit in the global frame (DESIGN.md raster convention)."""

    # the rasters' georeference plus the site origin, serialised flat with `site_origin_xy` first (the docstring
    # is the description in the committed export schemas)

    model_config = ConfigDict(json_schema_extra=_site_origin_first_in_schema)

    site_origin_xy: tuple[float, float] = Field(
        description="Global metres of the site origin: site = global - this."
    )

    # no return annotation: pydantic would take it for the serialisation schema instead of the model's
    @model_serializer(mode="wrap")
    def _site_origin_first(self, handler: SerializerFunctionWrapHandler):  # type: ignore[no-untyped-def]
        """The site origin first, then the raster fields (the order of every file written so far)."""
        data = handler(self)
        if not isinstance(data, dict) or "site_origin_xy" not in data:
            return data
        return {"site_origin_xy": data.pop("site_origin_xy"), **data}

    @classmethod
    def of(cls, raster: RasterGeoreference, *, site_origin_xy: Iterable[float]) -> "Georeference":
        """A raster georeference (e.g. `cama_pipeline.bev.read_georeference`) placed at a site origin."""
        return cls.model_validate({**raster.to_json(), "site_origin_xy": tuple(site_origin_xy)})


class AnnotationSet(BaseModel):
    """All map elements of one site with its georeference; ids are unique. Change it with upsert/remove (new sets)."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    format_version: Literal[1] = ANNOTATION_FORMAT_VERSION
    site_id: str = Field(min_length=1)
    georeference: Georeference
    elements: list[MapElement] = Field(default_factory=list)

    @model_validator(mode="after")
    def _unique_ids(self) -> Self:
        """Reject two elements with the same id."""
        seen: set[str] = set()
        for element in self.elements:
            if element.id in seen:
                raise ValueError(f"elements: duplicate element id {element.id!r}")
            seen.add(element.id)
        return self

    def by_class(self, cls: ElementClass) -> list[MapElement]:
        """Elements of one class, in stored order."""
        if cls not in ELEMENT_CLASSES:
            raise ValueError(f"cls: unknown element class {cls!r}; expected one of {ELEMENT_CLASSES}")
        return [element for element in self.elements if element.cls == cls]

    def by_id(self, element_id: str) -> MapElement:
        """The element with this id; KeyError naming the id and site when absent."""
        for element in self.elements:
            if element.id == element_id:
                return element
        raise KeyError(f"site {self.site_id!r} has no element with id {element_id!r}")

    def upsert(self, element: MapElement) -> "AnnotationSet":
        """A new set with `element` added, or replacing the element that has its id."""
        if any(existing.id == element.id for existing in self.elements):
            elements = [element if existing.id == element.id else existing for existing in self.elements]
        else:
            elements = [*self.elements, element]
        return self.model_copy(update={"elements": elements})

    def remove(self, element_id: str) -> "AnnotationSet":
        """A new set without the element of this id; KeyError when absent."""
        self.by_id(element_id)
        return self.model_copy(update={"elements": [e for e in self.elements if e.id != element_id]})

    def write_json(self, path: Path, *, indent: int | None = 2) -> None:
        """Write the set as JSON atomically (temporary file, then rename)."""
        atomic_write_bytes(Path(path), self.model_dump_json(indent=indent).encode("utf-8"))

    @classmethod
    def read_json(cls, path: Path) -> "AnnotationSet":
        """Read a set written by `write_json`; ValueError naming the file when it is invalid."""
        path = Path(path)
        try:
            return cls.model_validate_json(path.read_bytes())
        except ValidationError as error:
            raise ValueError(f"{path}: invalid annotation set: {error}") from error
