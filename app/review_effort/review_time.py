"""The simulated annotator's time on a proposer's output over validation sites: the second gate of VMA retraining.

Chamfer mAP says how close proposals are; what the loop is for is the annotators' time. For each validation site
(a synthetic site folder, or a BEV-only VMA site, with its true vectors; or a synthetic site's reconstruction,
`models.vma.validation`, whose truth is carried into the reconstruction's frame), the proposer's vectors at or above
`min_confidence` (as `cama propose` keeps them, made simple as in a proposals file) go into an in-memory queue
(`session.MemoryQueue`, the backend's queue order) and the scripted annotator corrects them towards the true
vectors cut to the observed cells, then draws the same truth from scratch. The figures are the seconds of both
workflows summed over the sites, and their ratio (the speed-up over drawing). `bench/end_to_end.py` measures the
same annotator through the real backend.
"""

from collections.abc import Callable, Sequence
from typing import Any

from app.review_effort.costs import ActionCosts
from app.review_effort.plan import Polyline, SimulationConfig
from app.review_effort.session import MemoryQueue, draw_from_scratch, work_queue
from app.review_effort.truth import observed_true_polylines
from models.vma.rasters import SiteRasters, load_site_rasters
from models.vma.validation import ValidationEntry, as_validation_site
from models.vma.vectors import Vector, simple_geometry

MIN_CONFIDENCE = 0.1
"""Proposals below this are dropped before review, as `cama propose` and the refresh job do by default."""


def review_queue(vectors: Sequence[Vector], min_confidence: float) -> tuple[list[Vector], MemoryQueue]:
    """The proposals an annotator gets from a proposer's `vectors` (at or above `min_confidence`, made simple as
    in a proposals file) and an in-memory queue of them, indexed as that list."""
    kept = [v for v in vectors if v.score >= min_confidence]
    simple = [v for v in (simple_geometry(v) for v in kept) if v is not None]
    return simple, MemoryQueue([(Polyline(v.cls, v.points), min(v.score, 1.0)) for v in simple])


def review_time(
    propose: Callable[[SiteRasters], list[Vector]],
    sites: Sequence[ValidationEntry],
    *,
    min_confidence: float = MIN_CONFIDENCE,
) -> dict[str, Any]:
    """{"correction_s", "drawing_s", "speed_up", "sites", "per_site_correction_s"} of the scripted annotator on
    `propose`'s output over each site's rasters (a path: its own; a `ValidationSite`: its `rasters`, a
    reconstruction's for a reconstructed site); the last is each site's correction time, in `sites`' order (the
    gate's confidence in a saving reads them)."""
    if not sites:
        raise ValueError("review_time: no validation sites given")
    config, costs = SimulationConfig(), ActionCosts()
    per_site, drawing_s = [], 0.0
    for entry in sites:
        site = as_validation_site(entry)
        rasters = load_site_rasters(site.rasters)
        truths = observed_true_polylines(site.site, rasters, site.frame)
        _, queue = review_queue(propose(rasters), min_confidence)
        per_site.append(work_queue(queue, truths, config, costs).total_s)
        drawing_s += draw_from_scratch(MemoryQueue([]), truths, config, costs).total_s
    correction_s = sum(per_site)
    return {
        "correction_s": correction_s,
        "drawing_s": drawing_s,
        "speed_up": drawing_s / correction_s if correction_s > 0 else None,
        "sites": [str(site) for site in sites],
        "per_site_correction_s": per_site,
    }
