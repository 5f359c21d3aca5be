"""What carrying dividers through the dash gap to the observed edge saves the annotator on reconstructions: the
dividers as before (carried at most `border_reach_m` along their end's course) and as the product carries them
(up to `divider_border_reach_m` along the course fitted to their last `divider_course_fit_m`), in one run.

On each `--site`'s reconstruction (a synthetic site with a finished workspace, `reconstruction_of`) the promoted
network of `--checkpoint` predicts once; both settings trace its masks, each proposed divider is scored against the
observed true divider it lies along (Chamfer distance, farthest point, vertices off the line, acceptance as it is:
`bench/boundary_evidence.py`'s `line_errors`), and the scripted annotator reviews both (`review_time`, the editor's
split included); the product's correction time is compared with the earlier setting's, with the confidence that
the saving holds across sites (`saving_confidence`). A checkpoint is refused on a site it saw (`ensure_unseen`).

Usage: .venv/bin/python bench/divider_carry.py --site data/synthetic/random-9113 [--site ...]
       [--checkpoint models/vma/element_masks/checkpoints] [--threads 2] [--out bench/results/divider_carry.json]
"""

import sys
from functools import partial
from pathlib import Path
from typing import Any

from models.vma.element_masks.net import ElementMaskNet
from models.vma.validation import ValidationSite

# the shared conditions: `bench` is a package at the repository root
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from bench.boundary_evidence import line_errors, setting_figures  # noqa: E402
from bench.vma_measures import against_baseline, compare_settings, setting_of, settings_bench  # noqa: E402

RESULTS = Path(__file__).parent / "results"
SETTINGS: dict[str, dict[str, Any]] = {
    "before": {"divider_border_reach_m": 2.0, "divider_course_fit_m": 0.0},
    "product": {},
}
"""Name of each setting in the results -> the `MaskInferenceConfig` fields it sets (the product: none)."""
BASELINE = "before"


def measure(sites: list[ValidationSite], model: ElementMaskNet) -> dict[str, Any]:
    """Both settings on every site (the network run once a site)."""
    settings = {name: setting_of(fields) for name, fields in SETTINGS.items()}
    compared = compare_settings(sites, model, settings, partial(line_errors, cls="divider"))
    return {
        "settings": {
            name: setting_figures(c["rows"], c["annotator"], counted="dividers")
            for name, c in compared.items()
        }
    }


def summary(figures: dict[str, Any]) -> dict[str, Any]:
    """Both settings, and the product's correction time against the earlier one's."""
    return {**figures, "against_before": against_baseline(figures["settings"], BASELINE)}


def main() -> None:
    settings_bench(
        "bench/divider_carry.py",
        __doc__.splitlines()[0],
        RESULTS / "divider_carry.json",
        measure,
        summary,
    )


if __name__ == "__main__":
    main()
