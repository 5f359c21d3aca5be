"""The raster georeference the tile code needs: where BEV pixel centres lie in global metres."""

import json
from pathlib import Path
from typing import Protocol

from pydantic import BaseModel, ConfigDict, Field, ValidationError


class GeoreferenceLike(Protocol):
    """Anything with the DESIGN.md raster fields (e.g. annotations.schema.Georeference)."""

    @property
    def origin_xy(self) -> tuple[float, float]: ...

    @property
    def resolution(self) -> float: ...

    @property
    def width(self) -> int: ...

    @property
    def height(self) -> int: ...


class RasterGeoreference(BaseModel):
    """A BEV raster's `georeference.json`: pixel (0, 0) centre in global metres; rows grow with -y."""

    model_config = ConfigDict(frozen=True, extra="ignore", allow_inf_nan=False)

    origin_xy: tuple[float, float] = Field(description="Global metres of raster pixel (0, 0)'s centre.")
    resolution: float = Field(gt=0.0, description="Metres per pixel.")
    width: int = Field(ge=1, description="Raster columns.")
    height: int = Field(ge=1, description="Raster rows.")

    @classmethod
    def of(cls, georef: GeoreferenceLike) -> "RasterGeoreference":
        """Copy the raster fields of any georeference-like object."""
        return cls(
            origin_xy=georef.origin_xy, resolution=georef.resolution, width=georef.width, height=georef.height
        )

    @classmethod
    def from_file(cls, path: Path) -> "RasterGeoreference":
        """Read a `georeference.json`; ValueError naming the file when it is missing a field or invalid."""
        path = Path(path)
        try:
            return cls.model_validate(json.loads(path.read_text(encoding="utf-8")))
        except (json.JSONDecodeError, ValidationError, TypeError) as error:
            raise ValueError(f"{path}: invalid raster georeference: {error}") from error
