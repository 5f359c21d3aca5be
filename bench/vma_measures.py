"""What the VMA benchmarks share: damaged and reconstructed conditions of a proposer, scored the same way.

`bench/vma_masks.py` (one checkpoint against the rule-based proposer) and `bench/vma_loop.py` (the rounds) both
score a proposer on held-out BEV sites with reconstruction-like damage and on the surface stage's reconstructed
rasters of full synthetic sites; this module is that one definition of both conditions.
"""

import argparse
import platform
import time
from collections.abc import Callable, Mapping
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import torch

from app.review_effort.plan import Polyline, SimulationConfig
from app.review_effort.review_time import review_time
from app.review_effort.truth import observed_true_polylines
from cama_pipeline.io import atomic_write_json
from cama_pipeline.site_identity import SeenSiteError
from models.vma.checkpoint import ensure_unseen
from models.vma.degrade import DegradeConfig, degrade_rasters
from models.vma.element_masks.checkpoint import MaskCheckpoint, load_mask_checkpoint
from models.vma.element_masks.net import ElementMaskNet
from models.vma.element_masks.propose import (
    MaskInferenceConfig,
    predict_probabilities,
    vectors_from_probabilities,
)
from models.vma.evaluate import evaluate_sites
from models.vma.gate import saving_confidence
from models.vma.rasters import SiteRasters, load_site_rasters, vector_map_of
from models.vma.validation import ValidationSite, reconstruction_of, true_vectors
from models.vma.vectors import Vector, read_vectors

Proposer = Callable[[SiteRasters], list[Vector]]


def unseen_mask_checkpoint(path: Path, sites: list[Path]) -> MaskCheckpoint:
    """The element-mask network of `path` (a version folder or a registry's promoted one), refused
    (`ensure_unseen`) when it trained on any of `sites`: a bench never scores a network on what it saw."""
    checkpoint = load_mask_checkpoint(path)
    for site in sites:
        ensure_unseen(checkpoint, site)
    return checkpoint


def on_damaged(propose: Proposer) -> Proposer:
    """The proposer on the site's rasters with `bench/vma.py`'s damage (default strengths, seeded by name)."""

    def run(rasters: SiteRasters) -> list[Vector]:
        return propose(degrade_rasters(rasters, DegradeConfig(seed=sum(rasters.name.encode()))))

    return run


def reconstructed_figures(propose: Proposer, reconstructions: list[ValidationSite]) -> dict[str, Any]:
    """Chamfer-AP against all true vectors in the reconstructed extent and against their observed parts (over
    all sites and per site: one bad site hides in a mean), and the annotator's speed-up, over the reconstructed
    rasters of `reconstructions` (`reconstruction_of`, made once by the caller for all its proposers)."""
    all_truth, observed_truth = [], []
    for site in reconstructions:
        rasters = load_site_rasters(site.rasters)
        truths = read_vectors(vector_map_of(site.site))
        seen = true_vectors(site, rasters)
        predictions = propose(rasters)
        all_truth.append((predictions, truths, rasters.extent()))
        observed_truth.append((predictions, seen, rasters.extent()))
    keys = ("mean_ap", "class_ap", "confidence_bins")
    per_site = {
        str(site.site): {k: v for k, v in evaluate_sites([scored]).items() if k in ("mean_ap", "class_ap")}
        for site, scored in zip(reconstructions, observed_truth, strict=True)
    }
    return {
        "all_truth": {k: v for k, v in evaluate_sites(all_truth).items() if k in keys},
        "observed_truth": {
            **{k: v for k, v in evaluate_sites(observed_truth).items() if k in keys},
            "per_site": per_site,
        },
        "annotator": review_time(propose, reconstructions),
        "sites": [str(s.site) for s in reconstructions],
    }


Setting = Callable[[MaskInferenceConfig], MaskInferenceConfig]
"""A change of the product's inference settings (the default `MaskInferenceConfig`)."""


def setting_of(fields: dict[str, Any]) -> Setting:
    """The setting that changes these `MaskInferenceConfig` fields."""
    return lambda config: replace(config, **fields)


def against_baseline(figures: dict[str, dict[str, Any]], baseline: str) -> dict[str, dict[str, Any]]:
    """Each setting's correction time against the `baseline` setting's, with the confidence that its saving holds
    across sites (`saving_confidence`, the gate's bootstrap)."""
    base = figures[baseline]
    return {
        name: {
            "correction_ratio": f["correction_s"] / base["correction_s"],
            "saving_confidence": saving_confidence(base["per_site_correction_s"], f["per_site_correction_s"]),
        }
        for name, f in figures.items()
        if name != baseline
    }


ElementErrors = Callable[[list[Vector], list[Polyline], SimulationConfig], list[dict[str, Any]]]
"""One row per proposal of interest, scored against the observed true elements of its site."""


def compare_settings(
    sites: list[ValidationSite],
    model: ElementMaskNet,
    settings: Mapping[str, Setting],
    element_errors: ElementErrors,
) -> dict[str, dict[str, Any]]:
    """Each named setting of the element-mask network's tracing on every reconstruction in one run, the network
    run once a site for all of them: per setting the `element_errors` rows over all sites and the scripted
    annotator's review (`review_time`)."""
    probabilities: dict[str, np.ndarray] = {}

    def proposer(setting: Setting) -> Proposer:
        def propose(rasters: SiteRasters) -> list[Vector]:
            config = setting(MaskInferenceConfig())
            key = rasters.georeference.model_dump_json()  # where the raster lies: one per site
            if key not in probabilities:
                probabilities[key] = predict_probabilities(model, rasters, config)
            return vectors_from_probabilities(rasters, probabilities[key], config)

        return propose

    config, compared = SimulationConfig(), {}
    for name, setting in settings.items():
        propose, rows = proposer(setting), []
        for site in sites:
            rasters = load_site_rasters(site.rasters)
            rows += element_errors(
                propose(rasters), observed_true_polylines(site.site, rasters, site.frame), config
            )
        annotator = review_time(propose, sites)
        compared[name] = {"rows": rows, "annotator": annotator}
        print(
            f"{name}: {len(rows)} elements scored, {annotator['correction_s']:.1f} s of correction "
            f"({annotator['speed_up']:.2f}x)",
            flush=True,
        )
    return compared


def settings_bench(
    script: str,
    description: str,
    default_out: Path,
    measure: Callable[[list[ValidationSite], ElementMaskNet], dict[str, Any]],
    summary: Callable[[dict[str, Any]], dict[str, Any]],
) -> None:
    """The command line of a bench that compares tracing settings of the element-mask network on reconstructions:
    `--site` (repeatable), `--checkpoint`, `--threads`, `--out`. The checkpoint is refused on a site it saw (exit 2,
    the site named, nothing written); the
    report (the command, checkpoint and sites, the `summary` of `measure`'s figures, the machine and the run's
    seconds) is written atomically."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument(
        "--site", type=Path, action="append", required=True, help="reconstructed site (repeatable)"
    )
    parser.add_argument("--checkpoint", type=Path, default=Path("models/vma/element_masks/checkpoints"))
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--out", type=Path, default=default_out)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    try:
        checkpoint = unseen_mask_checkpoint(args.checkpoint, args.site)
    except SeenSiteError as error:
        parser.exit(2, f"{script}: {error}\n")
    started = time.perf_counter()
    figures = measure([reconstruction_of(site) for site in args.site], checkpoint.model)
    report = {
        "command": f"python {script} "
        + "".join(f"--site {site} " for site in args.site)
        + f"--checkpoint {args.checkpoint} --threads {args.threads}",
        "checkpoint": str(checkpoint.path),
        "sites": [str(site) for site in args.site],
        **summary(figures),
        "machine": {"cpu_threads": args.threads, "platform": platform.platform(), "device": "cpu"},
        "seconds": round(time.perf_counter() - started, 1),
    }
    atomic_write_json(args.out, report)
    print(f"written to {args.out}")
