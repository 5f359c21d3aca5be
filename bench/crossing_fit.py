"""How the element-mask proposer's crossings fit on reconstructions: the smallest rectangle round the stripes against
the block read from them (`MaskInferenceConfig.crossing_fit`, `models.vma.crossing_block`), in one run.

On each `--site`'s reconstruction (a synthetic site with a finished workspace, `reconstruction_of`) the promoted
network of `--checkpoint` predicts once; both fits trace its masks with the product's other settings. Per fit: each
proposed crossing (at the review's confidence floor) against the observed true crossing it overlaps most (IoU,
Chamfer distance, and whether the scripted annotator would accept its shape as it is:
Chamfer <= 0.25 m, no point beyond 0.5 m), and the annotator's correction time over all elements per site
(`review_time`), with the ratio of the two fits' totals. A checkpoint is refused on a site it saw (`ensure_unseen`).

Usage: .venv/bin/python bench/crossing_fit.py --site data/synthetic/random-9113 [--site ...]
       [--checkpoint models/vma/element_masks/checkpoints] [--threads 2] [--out bench/results/crossing_fit.json]
"""

import argparse
import platform
import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import torch
from shapely.geometry import Polygon

from app.review_effort.plan import Polyline, SimulationConfig, acceptable_as_is, chamfer
from app.review_effort.review_time import MIN_CONFIDENCE, review_time
from app.review_effort.truth import observed_true_polylines
from cama_pipeline.io import atomic_write_json
from models.vma.element_masks.propose import inference_for, predict_probabilities, vectors_from_probabilities
from models.vma.rasters import SiteRasters, load_site_rasters
from models.vma.validation import ValidationSite, reconstruction_of
from models.vma.vectors import Vector

# the shared conditions: `bench` is a package at the repository root
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from bench.vma_measures import unseen_mask_checkpoint  # noqa: E402

RESULTS = Path(__file__).parent / "results"
FITS = ("rectangle", "stripes")


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


def measure(sites: list[ValidationSite], model: torch.nn.Module) -> dict[str, Any]:
    """Both fits on every site (the network run once a site)."""
    probabilities: dict[str, np.ndarray] = {}

    def proposer(fit: str):
        def propose(rasters: SiteRasters) -> list[Vector]:
            config = replace(inference_for(rasters), crossing_fit=fit)
            key = rasters.georeference.model_dump_json()  # where the raster lies: one per site
            if key not in probabilities:
                probabilities[key] = predict_probabilities(model, rasters, config)
            return vectors_from_probabilities(rasters, probabilities[key], config)

        return propose

    config, figures = SimulationConfig(), {}
    for fit in FITS:
        propose, rows = proposer(fit), []
        for site in sites:
            rasters = load_site_rasters(site.rasters)
            rows += crossing_errors(
                propose(rasters), observed_true_polylines(site.site, rasters, site.frame), config
            )
        figures[fit] = fit_figures(rows, review_time(propose, sites))
        print(
            f"{fit}: {figures[fit]['crossings']} crossings, IoU {figures[fit]['mean_iou']:.3f}, "
            f"{figures[fit]['correction_s']:.1f} s of correction ({figures[fit]['speed_up']:.2f}x)",
            flush=True,
        )
    return figures


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--site", type=Path, action="append", required=True, help="reconstructed site (repeatable)"
    )
    parser.add_argument("--checkpoint", type=Path, default=Path("models/vma/element_masks/checkpoints"))
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--out", type=Path, default=RESULTS / "crossing_fit.json")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    checkpoint = unseen_mask_checkpoint(args.checkpoint, args.site)
    started = time.perf_counter()
    figures = measure([reconstruction_of(site) for site in args.site], checkpoint.model)
    report = {
        "command": "python bench/crossing_fit.py "
        + "".join(f"--site {site} " for site in args.site)
        + f"--checkpoint {args.checkpoint} --threads {args.threads}",
        "checkpoint": str(checkpoint.path),
        "sites": [str(site) for site in args.site],
        "fits": figures,
        "correction_ratio_stripes_to_rectangle": figures["stripes"]["correction_s"]
        / figures["rectangle"]["correction_s"],
        "machine": {"cpu_threads": args.threads, "platform": platform.platform(), "device": "cpu"},
        "seconds": round(time.perf_counter() - started, 1),
    }
    atomic_write_json(args.out, report)
    print(f"written to {args.out}")


if __name__ == "__main__":
    sys.exit(main())
