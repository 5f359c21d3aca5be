"""How the element-mask proposer's crossings fit on reconstructions: the smallest rectangle round the stripes, the
block read from them, and that block only where it is narrower than the rectangle (`MaskInferenceConfig.crossing_fit`,
`models.vma.crossing_block`), in one run.

On each `--site`'s reconstruction (a synthetic site with a finished workspace, `reconstruction_of`) the promoted
network of `--checkpoint` predicts once; every fit traces its masks with the product's other settings. Per fit: each
proposed crossing (at the review's confidence floor) against the observed true crossing it overlaps most (IoU,
Chamfer distance, and whether the scripted annotator would accept its shape as it is:
Chamfer <= 0.25 m, no point beyond 0.5 m), and the annotator's correction time over all elements per site
(`review_time`), with each fit's total against the rectangle's and the confidence that its saving holds across
sites (`saving_confidence`, the gate's bootstrap). A checkpoint is refused on a site it saw (`ensure_unseen`).

Usage: .venv/bin/python bench/crossing_fit.py --site data/synthetic/random-9113 [--site ...]
       [--checkpoint models/vma/element_masks/checkpoints] [--threads 2] [--out bench/results/crossing_fit.json]
"""

import sys
from pathlib import Path
from typing import Any, get_args

import numpy as np
from shapely.geometry import Polygon

from app.review_effort.plan import Polyline, SimulationConfig, acceptable_as_is, chamfer
from app.review_effort.review_time import MIN_CONFIDENCE
from models.vma.element_masks.net import ElementMaskNet
from models.vma.element_masks.propose import CrossingFit
from models.vma.validation import ValidationSite
from models.vma.vectors import Vector

# the shared conditions: `bench` is a package at the repository root
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from bench.vma_measures import (  # noqa: E402
    Setting,
    against_baseline,
    compare_settings,
    setting_of,
    settings_bench,
)

RESULTS = Path(__file__).parent / "results"
FITS: tuple[CrossingFit, ...] = get_args(CrossingFit)


def crossing_errors(
    proposals: list[Vector], truths: list[Polyline], config: SimulationConfig
) -> list[dict[str, Any]]:
    """Each proposed crossing against the true crossing it overlaps most (none overlapped: left out)."""
    rings = [(t, Polygon(t.points)) for t in truths if t.cls == "ped_crossing"]
    rows = []
    for vector in proposals:
        if vector.cls != "ped_crossing" or vector.score < MIN_CONFIDENCE:
            continue
        shape = Polygon(vector.points)
        overlaps = [(shape.intersection(ring).area, truth, ring) for truth, ring in rings]
        area, truth, ring = max(overlaps, key=lambda o: o[0], default=(0.0, None, None))
        if truth is None or area <= 0:
            continue
        proposal = Polyline(vector.cls, vector.points)
        rows.append(
            {
                "iou": area / shape.union(ring).area,
                "chamfer_m": chamfer(proposal, truth),
                "acceptable": acceptable_as_is(proposal, truth, config),
            }
        )
    return rows


def fit_figures(rows: list[dict[str, Any]], annotator: dict[str, Any]) -> dict[str, Any]:
    """The crossings' means and the annotator's totals of one fit."""
    return {
        "crossings": len(rows),
        "mean_iou": float(np.mean([r["iou"] for r in rows])) if rows else None,
        "mean_chamfer_m": float(np.mean([r["chamfer_m"] for r in rows])) if rows else None,
        "acceptable_share": float(np.mean([r["acceptable"] for r in rows])) if rows else None,
        "correction_s": annotator["correction_s"],
        "drawing_s": annotator["drawing_s"],
        "speed_up": annotator["speed_up"],
        "per_site_correction_s": annotator["per_site_correction_s"],
    }


def measure(sites: list[ValidationSite], model: ElementMaskNet) -> dict[str, Any]:
    """Both fits on every site (the network run once a site)."""
    settings: dict[str, Setting] = {fit: setting_of({"crossing_fit": fit}) for fit in FITS}
    compared = compare_settings(sites, model, settings, crossing_errors)
    return {fit: fit_figures(c["rows"], c["annotator"]) for fit, c in compared.items()}


def summary(figures: dict[str, Any]) -> dict[str, Any]:
    """The report's figures: every fit, and each one's correction time against the rectangle's with the confidence
    that its saving holds."""
    return {
        "fits": figures,
        "correction_ratio_stripes_to_rectangle": figures["stripes"]["correction_s"]
        / figures["rectangle"]["correction_s"],
        "against_rectangle": against_baseline(figures, "rectangle"),
    }


def main() -> None:
    settings_bench(
        "bench/crossing_fit.py", __doc__.splitlines()[0], RESULTS / "crossing_fit.json", measure, summary
    )


if __name__ == "__main__":
    main()
