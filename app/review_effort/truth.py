"""The truth a simulated annotator works towards: a synthetic site's true vectors, as 2D polylines."""

from pathlib import Path

import numpy as np

from app.review_effort.plan import Polyline
from cama_pipeline.evaluate.frame import ReconstructionFrame
from cama_pipeline.evaluate.inputs import load_vector_map
from models.vma.rasters import SiteRasters, vector_map_of
from models.vma.validation import observed_truth


def true_polylines(site: Path) -> list[Polyline]:
    """The generator's true vectors of a synthetic site or a BEV-only VMA site (global metres, 2D)."""
    elements = load_vector_map(vector_map_of(Path(site)))
    return [Polyline(e.cls, np.asarray(e.points)[:, :2]) for e in elements]


def observed_true_polylines(
    site: Path, rasters: SiteRasters, frame: ReconstructionFrame | None = None
) -> list[Polyline]:
    """The site's true vectors carried into the reconstruction's `frame` (None: left in the world's; see
    `cama_pipeline.evaluate.frame`: an annotator sees the rasters, not the world) and cut to the cells `rasters` (a
    reconstruction's, loaded by the caller, who proposes on them too) observed (nobody draws road that no camera
    saw): the truth the VMA gate scores proposals against (`models.vma.validation.observed_truth`), as polylines."""
    return [Polyline(v.cls, v.points) for v in observed_truth(site, rasters, frame)]
