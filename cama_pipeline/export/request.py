"""What an export is asked to write (`ExportRequest`) and what it wrote (`ExportResult`)."""

from dataclasses import dataclass, field
from enum import StrEnum
from pathlib import Path

import numpy as np

from annotations.cama_cut import DEFAULT_OBSERVED_RADIUS_M
from annotations.kerb_evidence import check_semantic
from annotations.lanelet2_format import MapProjection
from annotations.schema import AnnotationSet
from cama_pipeline.data.map_origins import NUSCENES_MAP_ORIGINS
from cama_pipeline.data.masks import MaskChoice


class ExportFormat(StrEnum):
    """The formats that leave the system."""

    cama = "cama"
    """CAMA's public release layout (`all_clips/<scene>/maps`, `odometry`, optional clip data)."""
    maptr = "maptr"
    """One JSON file of per-sample vectors in each sample's ego frame (MapTR's training targets)."""
    nuscenes_cama = "nuscenes-cama"
    """A nuScenes root whose version folder holds the refined ego poses and the per-sample map vectors."""
    lanelet2 = "lanelet2"
    """An OSM file with Lanelet2's tagging (boundaries and crosswalks; no lanelets)."""


FORMATS_NEEDING_DATASET: frozenset[ExportFormat] = frozenset(
    {ExportFormat.cama, ExportFormat.maptr, ExportFormat.nuscenes_cama}
)
"""Formats that carry poses or per-sample data, so they need the data set (and, for refined poses, the
workspace's SfM outputs)."""


class PoseChoice(StrEnum):
    """Which ego poses an export writes."""

    refined = "refined"
    """SfM poses, and WIGO corrected by the SfM keyframes between them (`cama_pipeline.refined_poses`)."""
    coarse = "coarse"
    """The data set's logged ego poses: only when asked for."""


class CamaMode(StrEnum):
    """CAMA's two map modes."""

    clip = "clip"
    """One 300 m map per scene (`scmv` odometry)."""
    site = "site"
    """One 600 m map per site, cut per scene (`mcmv` odometry, `site2clip/`)."""


@dataclass(frozen=True)
class ExportRequest:
    """One export: the annotation set, where to write it, in which format, and what it takes from the
    reconstruction. Validated on construction (ValueError naming the field)."""

    annotations: AnnotationSet
    """The elements to export (site coordinates, with the site's georeference)."""
    out: Path
    """cama, nuscenes-cama: the output folder; maptr: the JSON file; lanelet2: the .osm file."""
    format: ExportFormat = ExportFormat.cama
    dataset_root: Path | None = None
    """The data set (nuScenes layout) the site was reconstructed from; cama, maptr and nuscenes-cama need it."""
    workspace: Path | None = None
    """The workspace with the SfM outputs (default: the data set's, beside it)."""
    site_id: str | None = None
    """The site whose reconstruction gives the poses (default: the annotation set's, or the workspace's only one)."""
    poses: PoseChoice = PoseChoice.refined
    elevation: np.ndarray | None = field(default=None, compare=False, repr=False)
    """The site's (H, W) elevation raster in the annotation set's georeference (cama's map height)."""
    semantic: np.ndarray | None = field(default=None, compare=False, repr=False)
    """lanelet2: the site's (H, W) semantic BEV raster (`cama_pipeline.semantics` ids, 255 unobserved) in the
    annotation set's georeference; each boundary is then written as a kerb or a road border by what it shows
    (`annotations.kerb_evidence`). None: every boundary is an assumed kerb."""
    scenes: tuple[str, ...] | None = None
    """Only these scenes (default: the site's scenes with refined poses; every scene with coarse poses)."""
    cama_mode: CamaMode = CamaMode.clip
    observed_radius_m: float = DEFAULT_OBSERVED_RADIUS_M
    """cama: a scene's labels are the elements within this distance of its cameras' trajectories (the surface
    stage's ray range by default), clipped there."""
    site_name: str | None = None
    """cama: the site's name in `site2clip/` (default: the reconstruction's site id, else the annotation set's)."""
    with_clip_data: bool = False
    """cama: also write each scene's images, lane masks (CAMA's ids) and attribute.json."""
    masks: MaskChoice = "auto"
    """Where clip data's lane instance masks come from (`cama_pipeline.data.masks`)."""
    origin_lat_lon: tuple[float, float] | None = None
    """lanelet2: the geographic origin (latitude, longitude) of the site's global frame's (0, 0). None: the origin
    of `origin_location`, else of the site's own location when it is a nuScenes one (the site manifest's
    `log.location`, `cama_pipeline.data.map_origins`), else the export is refused."""
    origin_location: str | None = None
    """lanelet2: a nuScenes location whose map origin to use (`NUSCENES_MAP_ORIGINS`), instead of a LAT,LON."""
    projection: MapProjection | None = None
    """lanelet2: how the global frame lies on the Earth around the origin. None: local (a tangent plane, as
    nuScenes' maps) for a nuScenes location's origin, utm for an `origin_lat_lon` given."""
    overwrite: bool = False
    """Replace an existing export at `out` (else it is an error)."""
    show_progress: bool = False
    """A progress bar (progress lines when output is not a terminal) for the writers that take long."""

    def __post_init__(self) -> None:
        if self.format in FORMATS_NEEDING_DATASET and self.dataset_root is None:
            raise ValueError(f"--format {self.format.value} needs --dataset ROOT (its poses and samples)")
        if self.with_clip_data and self.format is not ExportFormat.cama:
            raise ValueError("--with-clip-data: only for --format cama")
        if self.origin_lat_lon is not None and self.origin_location is not None:
            raise ValueError("--origin: either LAT,LON or a nuScenes location, not both")
        if self.origin_location is not None and self.origin_location not in NUSCENES_MAP_ORIGINS:
            raise ValueError(
                f"--origin {self.origin_location!r}: not LAT,LON nor a nuScenes location "
                f"({', '.join(NUSCENES_MAP_ORIGINS)})"
            )
        if self.format is not ExportFormat.lanelet2 and (
            self.origin_lat_lon is not None or self.origin_location is not None or self.projection is not None
        ):
            raise ValueError("--origin, --projection: only for --format lanelet2")
        if not (np.isfinite(self.observed_radius_m) and self.observed_radius_m > 0):
            raise ValueError(f"--observed-radius-m: expected a value > 0, got {self.observed_radius_m}")
        if self.semantic is not None:
            if self.format is not ExportFormat.lanelet2:
                raise ValueError("--semantic: only for --format lanelet2 (kerbs and road borders)")
            check_semantic(self.semantic, self.annotations.georeference)
        if self.scenes is not None and not self.scenes:
            raise ValueError("scenes: an empty list; leave it out for the site's scenes")


@dataclass(frozen=True)
class ExportResult:
    """What an export wrote."""

    path: Path
    """The export's final path (folder or file)."""
    format: ExportFormat
    poses: PoseChoice
    elements: int
    """Elements of the annotation set exported."""
    files: int
    """Files written under `path` (1 for a single-file format)."""
    summary: dict[str, object] = field(default_factory=dict)
    """The format writer's own counts (scenes, pose sources, tags), for the command's line and the job."""
