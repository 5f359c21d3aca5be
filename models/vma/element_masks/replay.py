"""Rehearsal for fine-tuning on corrections: a few of the version's own training sites, made again or read again.

Fine-tuning on the corrected elements of one or two sites teaches the network their geometry and, with nothing
else in the batches, lets it forget the variety it was trained on: in the loop of `bench/vma_loop.py` the
candidates of rounds 2 and 3 (trained on two and three corrected sites) were worse than their parent on the
validation sites (mAP 0.984 -> 0.979, the annotator's time 308 -> 338 s). Mixing crops of the parent's own
training data into every batch (rehearsal, as continual learning does) is meant to keep what it knew while the
corrections move it. Measured (README, "Rehearsal while retraining"): after three rounds the held-out BEV sites
gain with it on both sets of new sites tried, the annotator on the one reconstructed site loses, so
`MaskRetrainConfig.replay_share` is 0 by default.

The BEV-only generator sites a version trained on are named in its `data.seen_sites` by preset and seed, so they
are written again (`models.vma.bev_sites`, deterministic, about 10 s each) under a cache folder; a site whose
regenerated config no longer matches the recorded one (the generator changed since) is skipped with a warning
rather than replayed as something the version never saw.

The reconstructions a version trained on (`data.reconstructions`: the surface stage's rasters of generated sites,
against the truth their cameras observed) cannot be made again cheaply; they are read where they were, and one
whose site is gone or is no longer the generated site the version recorded is skipped with a warning. They are
what the product proposes on, so rehearsing them keeps what the network learned of reconstructions, which the BEV
sites alone do not (README, "Rehearsing reconstructions").
"""

import logging
from pathlib import Path

import numpy as np

from cama_pipeline.site.io import read_site_manifest
from cama_pipeline.site_identity import SiteIdentity, site_identity
from cama_pipeline.workspace import Workspace
from models.vma.bev_sites import BEV_PRESET, write_bev_site
from models.vma.checkpoint import VersionRecord, seen_sites
from models.vma.element_masks.config import MaskModelConfig
from models.vma.element_masks.train import MaskTrainingSite, load_mask_training_site
from models.vma.rasters import SiteInputError
from models.vma.validation import reconstruction_of

logger = logging.getLogger(__name__)


def replay_candidates(version: VersionRecord) -> list[SiteIdentity]:
    """The BEV-only generator sites `version` (and its parents) trained on, in seed order."""
    return sorted((s for s in seen_sites(version) if s.preset == BEV_PRESET), key=lambda s: s.seed)


def replay_sites(
    version: VersionRecord,
    root: Path,
    count: int,
    model_config: MaskModelConfig,
    damaged_copies: int,
    seed: int,
) -> list[MaskTrainingSite]:
    """`count` of `version`'s own BEV training sites (drawn with `seed`), written under `root/seed-<seed>` where
    missing, as training sites; fewer when it trained on fewer or a regenerated site no longer matches."""
    candidates = replay_candidates(version)
    if count <= 0 or not candidates:
        return []
    picked = np.random.default_rng(seed).permutation(len(candidates))[:count]
    out = []
    for identity in (candidates[int(k)] for k in sorted(picked)):
        folder = write_bev_site(identity.seed, Path(root) / f"seed-{identity.seed}")
        made = site_identity(folder)
        if (made.layout_digest, made.config_digest) != (identity.layout_digest, identity.config_digest):
            logger.warning(
                "replay: %s is not the site %s trained on (the generator changed since); not replayed",
                folder,
                version.path,
            )
            continue
        out.append(load_mask_training_site(folder, model_config, damaged_copies))
    return out


def reconstruction_candidates(version: VersionRecord) -> list[tuple[SiteIdentity, Path]]:
    """The reconstructions `version` itself trained on: each raster folder of its `data.reconstructions` with the
    recorded identity of the generated site it reconstructs (the one of the location its workspace's site manifest
    names), in seed order; a folder whose manifest is gone is skipped with a warning."""
    by_location = {site.location: site for site in seen_sites(version)}
    out = []
    for rasters in (Path(p) for p in version.meta.get("data", {}).get("reconstructions", [])):
        try:
            workspace, site_id = Workspace.locate(rasters)
            location = read_site_manifest(workspace.site_manifest(site_id))["location"]
        except (OSError, ValueError, KeyError, TypeError) as error:
            logger.warning("replay: %s: %s; not replayed", rasters, error)
            continue
        if location in by_location:
            out.append((by_location[location], rasters))
    return sorted(out, key=lambda item: item[0].seed)


def rehearsed_reconstructions(
    version: VersionRecord, count: int, model_config: MaskModelConfig, seed: int
) -> list[MaskTrainingSite]:
    """`count` of the reconstructions `version` trained on (drawn with `seed`) as training sites, read where they
    lie; fewer when it trained on fewer or one is gone or changed (each named in a warning)."""
    candidates = reconstruction_candidates(version)
    if count <= 0 or not candidates:
        return []
    picked = np.random.default_rng(seed).permutation(len(candidates))[:count]
    out = []
    for identity, rasters in (candidates[int(k)] for k in sorted(picked)):
        try:
            made = site_identity(Path(identity.path))
            site = reconstruction_of(Path(identity.path), Workspace.locate(rasters).workspace.root)
        except (FileNotFoundError, ValueError, SiteInputError) as error:
            logger.warning("replay: %s: %s; not replayed", identity.path, error)
            continue
        if (made.layout_digest, made.config_digest) != (identity.layout_digest, identity.config_digest) or (
            site.rasters.resolve() != rasters.resolve()
        ):
            logger.warning(
                "replay: %s is not the reconstruction %s trained on (%s); not replayed",
                identity.path,
                version.path,
                rasters,
            )
            continue
        out.append(load_mask_training_site(site, model_config, 0))
    return out
