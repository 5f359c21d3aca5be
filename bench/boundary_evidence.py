"""What the element-mask proposer's boundaries follow on reconstructions, in one run: the network's own band (the
product), the road's sharp edge next to observed ground (`MaskInferenceConfig.boundary_evidence = "road_edge"`, the
product until this bench), and that edge's band spanned over the unobserved strip between the road and the ground
(`across_kerb_gap`, `element_masks.propose.road_edge_band`).

On each `--site`'s reconstruction (a synthetic site with a finished workspace, `reconstruction_of`) the promoted
network of `--checkpoint` predicts once; every setting traces its masks with the product's other settings. Per
setting: each proposed boundary (at the review's confidence floor) against the observed true boundary it lies along
(mean distance within the annotator's match reach): its Chamfer distance, its farthest point from the truth, the
share of its vertices farther than the annotator's vertex tolerance (each one a drag), and whether the scripted
annotator would accept it as it is (Chamfer <= 0.25 m, no point beyond 0.5 m); then the annotator's correction time
over all elements per site (`review_time`). Each setting's total is compared with the road's edge's, with the
confidence that its saving holds across sites (`saving_confidence`, the gate's bootstrap). A checkpoint is refused
on a site it saw (`ensure_unseen`).

Usage: .venv/bin/python bench/boundary_evidence.py --site data/synthetic/random-9113 [--site ...]
       [--checkpoint models/vma/element_masks/checkpoints] [--threads 2] [--out bench/results/boundary_evidence.json]
"""

import sys
from pathlib import Path
from typing import Any

import numpy as np
from shapely.geometry import LineString, Point

from app.review_effort.plan import Polyline, SimulationConfig, acceptable_as_is, chamfer, worst_gap
from app.review_effort.review_time import MIN_CONFIDENCE
from models.vma.element_masks.net import ElementMaskNet
from models.vma.validation import ValidationSite
from models.vma.vectors import Vector

# the shared conditions: `bench` is a package at the repository root
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from bench.vma_measures import against_baseline, compare_settings, setting_of, settings_bench  # noqa: E402

RESULTS = Path(__file__).parent / "results"
SETTINGS: dict[str, dict[str, Any]] = {
    "network_band": {"boundary_evidence": "none"},
    "road_edge": {"boundary_evidence": "road_edge"},
    "across_gap": {"boundary_evidence": "road_edge", "across_kerb_gap": True},
}
"""Name of each setting in the results -> the `MaskInferenceConfig` fields it sets."""
BASELINE = "road_edge"


def boundary_errors(
    proposals: list[Vector], truths: list[Polyline], config: SimulationConfig
) -> list[dict[str, Any]]:
    """Each proposed boundary against the true boundary it lies along (none within `config.match_m`: left out)."""
    return line_errors(proposals, truths, config, "boundary")


def line_errors(
    proposals: list[Vector], truths: list[Polyline], config: SimulationConfig, cls: str
) -> list[dict[str, Any]]:
    """Each proposed line of class `cls` against the true one it lies along (none within `config.match_m`: left
    out): Chamfer distance, farthest point, share of vertices off the true line, acceptance as it is."""
    lines = [(t, LineString(t.points)) for t in truths if t.cls == cls]
    rows = []
    for vector in proposals:
        if vector.cls != cls or vector.score < MIN_CONFIDENCE or not lines:
            continue
        distances = [np.mean([line.distance(Point(p)) for p in vector.points]) for _, line in lines]
        nearest = int(np.argmin(distances))
        if distances[nearest] > config.match_m:
            continue
        truth, line = lines[nearest]
        proposal = Polyline(vector.cls, vector.points)
        off = [line.distance(Point(p)) > config.vertex_tolerance_m for p in vector.points]
        rows.append(
            {
                "chamfer_m": chamfer(proposal, truth),
                "worst_gap_m": worst_gap(proposal, truth),
                "vertices_off_share": float(np.mean(off)),
                "acceptable": acceptable_as_is(proposal, truth, config),
            }
        )
    return rows


def setting_figures(
    rows: list[dict[str, Any]], annotator: dict[str, Any], counted: str = "boundaries"
) -> dict[str, Any]:
    """The scored lines' means (their count under `counted`) and the annotator's totals of one setting."""

    def mean(key: str) -> float | None:
        return float(np.mean([r[key] for r in rows])) if rows else None

    return {
        counted: len(rows),
        "mean_chamfer_m": mean("chamfer_m"),
        "median_chamfer_m": float(np.median([r["chamfer_m"] for r in rows])) if rows else None,
        "mean_worst_gap_m": mean("worst_gap_m"),
        "vertices_off_share": mean("vertices_off_share"),
        "acceptable_share": mean("acceptable"),
        "correction_s": annotator["correction_s"],
        "drawing_s": annotator["drawing_s"],
        "speed_up": annotator["speed_up"],
        "per_site_correction_s": annotator["per_site_correction_s"],
    }


def measure(sites: list[ValidationSite], model: ElementMaskNet) -> dict[str, Any]:
    """Every setting on every site (the network run once a site)."""
    settings = {name: setting_of(fields) for name, fields in SETTINGS.items()}
    compared = compare_settings(sites, model, settings, boundary_errors)
    return {name: setting_figures(c["rows"], c["annotator"]) for name, c in compared.items()}


def summary(figures: dict[str, Any]) -> dict[str, Any]:
    """The report's figures: every setting, and each one's correction time against the road's edge's with the
    confidence that its saving holds."""
    return {"settings": figures, "against_road_edge": against_baseline(figures, BASELINE)}


def main() -> None:
    settings_bench(
        "bench/boundary_evidence.py",
        __doc__.splitlines()[0],
        RESULTS / "boundary_evidence.json",
        measure,
        summary,
    )


if __name__ == "__main__":
    main()
