"""What the VMA benchmarks share: damaged and reconstructed conditions of a proposer, scored the same way.

`bench/vma_masks.py` (one checkpoint against the rule-based proposer) and `bench/vma_loop.py` (the rounds) both
score a proposer on held-out BEV sites with reconstruction-like damage and on the surface stage's reconstructed
rasters of full synthetic sites; this module is that one definition of both conditions.
"""

from collections.abc import Callable
from pathlib import Path
from typing import Any

from app.review_effort.review_time import review_time
from models.vma.checkpoint import ensure_unseen
from models.vma.degrade import DegradeConfig, degrade_rasters
from models.vma.element_masks.checkpoint import MaskCheckpoint, load_mask_checkpoint
from models.vma.evaluate import evaluate_sites
from models.vma.rasters import SiteRasters, load_site_rasters, vector_map_of
from models.vma.validation import ValidationSite, true_vectors
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
