"""What the editor's split saves the scripted annotator on reconstructions: the same proposals reviewed with and
without it, in one run.

On each `--site`'s reconstruction (a synthetic site with a finished workspace, `reconstruction_of`) the promoted
network of `--checkpoint` proposes once with the product's settings, and the scripted annotator reviews those
proposals against the truth its cameras observed twice: without the split (`SimulationConfig.split = False`, the
annotator of the figures recorded before it was modelled) and with it (`app.review_effort.split`). Per setting:
the correction time, the speed-up over drawing every element from nothing, the splits made and the elements still
drawn; and the split's correction time against the baseline's with the confidence that the saving holds across
sites (`saving_confidence`, the gate's bootstrap). A checkpoint is refused on a site it saw (`ensure_unseen`).

Usage: .venv/bin/python bench/annotator_split.py --site data/synthetic/random-9201 [--site ...]
       [--checkpoint models/vma/element_masks/checkpoints] [--threads 2] [--out bench/results/annotator_split.json]
"""

import sys
from dataclasses import replace
from pathlib import Path
from typing import Any

from app.review_effort.costs import ActionCosts
from app.review_effort.plan import SimulationConfig
from app.review_effort.review_time import MIN_CONFIDENCE, review_queue
from app.review_effort.session import MemoryQueue, draw_from_scratch, work_queue
from app.review_effort.truth import observed_true_polylines
from models.vma.element_masks.net import ElementMaskNet
from models.vma.element_masks.propose import (
    MaskInferenceConfig,
    predict_probabilities,
    vectors_from_probabilities,
)
from models.vma.rasters import load_site_rasters
from models.vma.validation import ValidationSite

# the shared conditions: `bench` is a package at the repository root
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from bench.vma_measures import against_baseline, settings_bench  # noqa: E402

RESULTS = Path(__file__).parent / "results"
SETTINGS = {"no_split": False, "split": True}
"""Name of each annotator in the results -> whether it uses the editor's split."""
BASELINE = "no_split"


def measure(sites: list[ValidationSite], model: ElementMaskNet) -> dict[str, Any]:
    """Both annotators on every site's proposals (the network run once a site)."""
    costs, inference = ActionCosts(), MaskInferenceConfig()
    figures: dict[str, dict[str, Any]] = {
        name: {"per_site_correction_s": [], "splits": 0, "drawn": 0} for name in SETTINGS
    }
    drawing_s = 0.0
    for site in sites:
        rasters = load_site_rasters(site.rasters)
        truths = observed_true_polylines(site.site, rasters, site.frame)
        vectors = vectors_from_probabilities(
            rasters, predict_probabilities(model, rasters, inference), inference
        )
        drawing_s += draw_from_scratch(MemoryQueue([]), truths, SimulationConfig(), costs).total_s
        for name, split in SETTINGS.items():
            _, queue = review_queue(vectors, MIN_CONFIDENCE)
            log = work_queue(queue, truths, replace(SimulationConfig(), split=split), costs)
            figures[name]["per_site_correction_s"].append(log.total_s)
            figures[name]["splits"] += log.counts["splits"]
            figures[name]["drawn"] += log.counts["drawn"]
        print(
            f"{site.site}: "
            + ", ".join(f"{n} {f['per_site_correction_s'][-1]:.1f} s" for n, f in figures.items())
        )
    for figure in figures.values():
        figure["correction_s"] = sum(figure["per_site_correction_s"])
        figure["drawing_s"] = drawing_s
        figure["speed_up"] = drawing_s / figure["correction_s"] if figure["correction_s"] > 0 else None
    return {"settings": figures}


def summary(figures: dict[str, Any]) -> dict[str, Any]:
    """Both annotators, and the split's correction time against the annotator without it."""
    return {**figures, "against_no_split": against_baseline(figures["settings"], BASELINE)}


def main() -> None:
    settings_bench(
        "bench/annotator_split.py",
        __doc__.splitlines()[0],
        RESULTS / "annotator_split.json",
        measure,
        summary,
    )


if __name__ == "__main__":
    main()
