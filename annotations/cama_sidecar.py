"""Our georeference sidecar beside CAMA labels (our extension; CAMA's tools ignore it): what `cama import` needs to
put the labels back in site coordinates.

Version 1 (the older folder-per-site layout, no longer written; `cama import` still reads it, see
`annotations.cama_import`): `maps/georeference.json` with the site id and the Georeference of the exported raster;
label pixels are that raster's pixels.

Version 2 (the public release layout, `annotations.cama_release`): per scene `all_clips/<scene>/maps/
georeference.json`, and for the site map `site2clip/<site>_georeference.json`. Label pixels are the release map's
([u, v] = [(world y + S/2) / r, (world x + S/2) / r], world = global - `world_origin_global`), and
`georeference` is the annotation set's own (restored on import). `elevation_filled` names the PNG beside the
sidecar marking the cells of the elevation raster that were filled from their nearest observed cell (255) rather
than observed (0), indexed [v, u] like the raster.
"""

from pathlib import Path
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field

from annotations.cama_labels import read_json_file, validate_file
from annotations.schema import Georeference

ElevationSource = Literal["raster", "elements-mean"]


class CamaGeoreferenceFile(BaseModel):
    """`maps/georeference.json` (our extension): which site, and where its raster pixels sit."""

    model_config = ConfigDict(extra="forbid")

    format: Literal["cama-studio-georeference"] = "cama-studio-georeference"
    format_version: Literal[1] = 1
    site_id: str = Field(min_length=1)
    georeference: Georeference


class CamaReleaseGeoreference(BaseModel):
    """The version 2 sidecar of one release map (a scene's, or the site map): its frame and our site's."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)

    format: Literal["cama-studio-georeference"] = "cama-studio-georeference"
    format_version: Literal[2] = 2
    site_id: str = Field(min_length=1, description="The site the labels belong to (the export's site name).")
    scene: str | None = Field(description="The scene of this map; None for the site map.")
    mode: Literal["clip", "site"] = Field(
        description="clip: one map per scene (scmv); site: one per site (mcmv)."
    )
    georeference: Georeference = Field(description="The annotation set's georeference (restored on import).")
    world_origin_global: tuple[float, float, float] = Field(
        description="Global metres of the map's (and the odometry's) world origin; z is 0: z stays global."
    )
    map_side_m: float = Field(gt=0.0, description="Side S of the square map in metres.")
    resolution_m: float = Field(gt=0.0, description="Metres per map pixel.")
    cells: int = Field(ge=1, description="Pixels per side: the elevation raster is cells x cells.")
    observed_radius_m: float | None = Field(
        description="Radius of the scene's observed range (camera trajectory buffer); None for the site map."
    )
    elevation_filled: str = Field(
        min_length=1, description="PNG beside this file: 255 where the elevation cell was filled, [v, u]."
    )
    label_spacing_m: float | None = Field(
        default=None,
        gt=0.0,
        description="Label polylines were densified to at most this spacing (metres) so that a reader taking z at "
        "each point follows the surface; import drops the points that densifying added. None: written as is.",
    )
    elevation_source: ElevationSource = Field(
        description="raster: resampled from our elevation raster; elements-mean: no raster, the mean element z."
    )


def read_sidecar(path: Path) -> CamaGeoreferenceFile | CamaReleaseGeoreference:
    """A sidecar of either version; FileNotFoundError / ValueError naming the file and field."""
    data = read_json_file(path)
    version = data.get("format_version") if isinstance(data, dict) else None
    if version == 2:
        return validate_file(CamaReleaseGeoreference, data, path)
    return validate_file(CamaGeoreferenceFile, data, path)
