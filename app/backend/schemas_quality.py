"""Response shapes of the raster, lint, diff and figures endpoints (pydantic), separate from the ORM models."""

import logging

from pydantic import BaseModel, ConfigDict, Field

from app.backend.schemas import Point
from app.backend.tiles import PyramidInfo

logger = logging.getLogger(__name__)


class LayerPublic(BaseModel):
    """One raster layer of a site: its tile URL template, pyramid (levels, georeference) and legend."""

    name: str
    tile_url: str = Field(
        description="XYZ template, relative to the server; `v` busts caches when the source raster changes."
    )
    pyramid: PyramidInfo


class ElevationPublic(BaseModel):
    """Elevation at a point; `elevation_m` is null outside the raster or where the ground was unobserved."""

    xy: Point = Field(description="The query point in site metres.")
    global_xy: Point = Field(description="The query point in global metres.")
    elevation_m: float | None


class LintFindingPublic(BaseModel):
    """One lint problem: a stable code, its severity, the element ids involved and where to look (site metres)."""

    model_config = ConfigDict(frozen=True)

    code: str
    severity: str
    element_ids: list[int]
    location_xy: Point
    message: str


class LintRequest(BaseModel):
    """An on-demand lint run, optionally limited to findings located in a bounding box."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)

    bbox: tuple[float, float, float, float] | None = Field(
        default=None, description="xmin, ymin, xmax, ymax in site metres; null lints the whole site."
    )


class LintReport(BaseModel):
    """The findings of one lint run over a site's live elements."""

    site_id: int
    element_count: int
    findings: list[LintFindingPublic]
    pending_elements: int = Field(
        default=0,
        description="Elements changed since that this report has not linted yet (a request lints for at most "
        "CAMA_LINT_BUDGET_S; the next requests go on); their previous findings are kept. 0: complete.",
    )


class ProposalDiffPublic(BaseModel):
    """How an element's current geometry and class differ from the proposal it started as."""

    element_id: int
    proposal_class: str
    current_class: str
    state: str
    unchanged: bool
    class_changed: bool
    chamfer_m: float
    vertices_moved: int
    vertices_added: int
    vertices_removed: int
    mean_displacement_m: float


class ClassDiffSummary(BaseModel):
    """Proposal-to-final diffs of one proposal class over the reviewed (accepted/fixed/approved/returned) elements."""

    cls: str = Field(serialization_alias="class")
    elements: int
    unchanged: int
    class_changed: int
    mean_chamfer_m: float | None
    vertices_moved: int
    vertices_added: int
    vertices_removed: int


class AnnotatorFiguresPublic(BaseModel):
    """Figures of one annotator for one class (`cls == "all"`: every class); rates null when undefined."""

    model_config = ConfigDict(from_attributes=True)

    author: str
    cls: str = Field(serialization_alias="class")
    items_handled: int
    active_hours: float
    items_per_hour: float | None
    proposals_reviewed: int
    accepted_unchanged: int
    accepted_unchanged_fraction: float | None
    fixes: int
    mean_fix_displacement_m: float | None
