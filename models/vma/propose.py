"""`cama propose` as a function: a site's rasters -> proposals JSON (an AnnotationSet of `proposal` elements).

Output coordinates are site metres: the site origin is the generator's `manifest.json` `config.site_origin_xy`
when the site has one, else the raster origin. Beside it, `<out>.fingerprint` holds the digest of what made
it (rasters, checkpoint version, proposer settings, the code; `cama_pipeline.fingerprints`); a rerun with the
same digest does nothing unless `overwrite`.
"""

import json
import logging
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Literal

from annotations import Georeference
from cama_pipeline.bev import georeference_path, layer_path
from cama_pipeline.code_version import code_version
from cama_pipeline.fingerprints import file_stats, fingerprint, is_up_to_date, mark_done
from cama_pipeline.surface.outputs import is_surface_bev
from models.vma.checkpoint import META, load_checkpoint
from models.vma.element_masks.checkpoint import load_mask_checkpoint
from models.vma.element_masks.propose import predict_site_masks
from models.vma.infer import InferenceConfig, predict_site
from models.vma.rasters import SiteInputError, SiteRasters, load_site_rasters, raster_dir_of
from models.vma.rule_based import BoundarySource, RuleConfig, propose_rule_based
from models.vma.shipped import SHIPPED_MASK_REGISTRY, checkpoint_label, resolve_checkpoint
from models.vma.train import device_for
from models.vma.vectors import Vector, proposals_as_annotations

logger = logging.getLogger(__name__)

Proposer = Literal["learned", "rule", "masks"]
PROPOSERS: tuple[str, ...] = ("learned", "rule", "masks")
"""The learned MapTR-style model, the rule-based proposer, the element-mask network (`models.vma.element_masks`)."""


@dataclass(frozen=True)
class ProposeResult:
    """Where the proposals went and what they hold."""

    out: Path
    count: int
    seconds: float
    skipped: bool
    checkpoint: Path | None
    """The checkpoint version folder the learned or element-mask proposer used; None for the rule-based one."""


def site_origin_of(site: Path, rasters: SiteRasters) -> tuple[float, float]:
    """The site origin from a generated site's manifest, else the raster's origin."""
    manifest = Path(site) / "manifest.json"
    if manifest.is_file():
        try:
            x, y = json.loads(manifest.read_text(encoding="utf-8"))["config"]["site_origin_xy"]
            return float(x), float(y)
        except (json.JSONDecodeError, KeyError, TypeError, ValueError) as err:
            raise SiteInputError(f"{manifest}: config.site_origin_xy must be [x, y]: {err!r}") from None
    return rasters.origin_xy


def boundary_source_for(site: Path) -> BoundarySource:
    """Where boundaries come from by default: the road's edge on reconstructed rasters (a surface stage's `bev/`,
    whose curb labels are smeared), the curb class on a generator's sharp ground-truth rasters. `cama propose`
    and `cama run` both use this, so the same rasters give the same proposals from either command."""
    return "road_edge" if is_surface_bev(raster_dir_of(site)) else "curb"


def propose(
    site: Path,
    out: Path,
    *,
    proposer: Proposer = "masks",
    checkpoint: Path | None = None,
    min_confidence: float = 0.1,
    inference: InferenceConfig | None = None,
    rule: RuleConfig | None = None,
    overwrite: bool = False,
    show_progress: bool = True,
) -> ProposeResult:
    """Propose vectors for a site with the learned model or the element-mask network (`checkpoint`: a registry or
    version folder of that kind, None for the one shipped) or the rule-based proposer; `rule` sets the rule-based
    proposer, and the learned model's candidates when it is anchored (the element-mask network traces its own
    masks, whatever `rule` says)."""
    site, out = Path(site), Path(out)
    if proposer not in PROPOSERS:
        raise ValueError(f"proposer must be one of {PROPOSERS}, got {proposer!r}")
    rule = rule or RuleConfig(boundary_source=boundary_source_for(site))
    version = None
    if proposer == "learned":
        version = resolve_checkpoint(checkpoint)
    elif proposer == "masks":
        version = resolve_checkpoint(checkpoint, SHIPPED_MASK_REGISTRY)
    raster_dir = raster_dir_of(site)
    inputs = [
        layer_path(raster_dir, "semantic"),
        layer_path(raster_dir, "photometric"),
        georeference_path(raster_dir),
    ]
    if version is not None:
        logger.info("VMA checkpoint %s", checkpoint_label(version))
        inputs.append(version / META)
    settings = [
        proposer,
        min_confidence,
        asdict(inference or InferenceConfig()),
        asdict(rule),
    ]
    digest = fingerprint(code_version("models.vma"), settings, file_stats([*inputs, site / "manifest.json"]))
    if not overwrite and is_up_to_date(out, digest):
        logger.info("%s is up to date; nothing to do", out)
        return ProposeResult(out, -1, 0.0, skipped=True, checkpoint=version)
    started = time.perf_counter()
    rasters = load_site_rasters(site)
    vectors: list[Vector]
    if proposer == "masks" and version is not None:
        masks = load_mask_checkpoint(version, device=str(device_for()))
        vectors = predict_site_masks(masks.model, rasters, show_progress=show_progress)
        author = f"vma-masks-{masks.path.name}"
    elif version is not None:
        loaded = load_checkpoint(version, device=str(device_for()))
        inference = replace(inference or InferenceConfig(), rule=rule)
        vectors = predict_site(loaded.model, rasters, inference, show_progress=show_progress)
        author = f"vma-{loaded.path.name}"
    else:
        vectors = propose_rule_based(rasters, rule)
        author = "vma-rule-based"
    vectors = [v for v in vectors if v.score >= min_confidence]
    georeference = Georeference.of(rasters.georeference, site_origin_xy=site_origin_of(site, rasters))
    proposals = proposals_as_annotations(vectors, georeference, site.name or "site", author)
    proposals.write_json(out)
    mark_done(out, digest)
    seconds = time.perf_counter() - started
    logger.info("wrote %d proposals to %s in %.1f s", len(vectors), out, seconds)
    return ProposeResult(out, len(vectors), seconds, skipped=False, checkpoint=version)
