"""The pairs stage: for every site of the workspace, sequential + HSP pairs of its keyframe images."""

import logging
import time
from dataclasses import asdict, dataclass
from pathlib import Path

from cama_pipeline.cameras import CameraView, site_views
from cama_pipeline.code_version import code_version
from cama_pipeline.data import load_dataset
from cama_pipeline.pairs.config import PairsConfig
from cama_pipeline.pairs.hsp import spatial_pairs
from cama_pipeline.pairs.io import PAIR_REASONS, pairs_dir, read_pairs, write_pairs
from cama_pipeline.pairs.repeats import repeat_pairs, repeated_views
from cama_pipeline.pairs.sequential import Pair, sequential_pairs
from cama_pipeline.site.outputs import SitesRun
from cama_pipeline.site.workspace import (
    default_workspace,
    file_stats,
    fingerprint,
    read_site_manifest,
    read_sites_index,
    site_manifest_path,
    sites_index_path,
    stored_fingerprint,
)

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class SitePairs:
    """The pairs of one site and how they were chosen."""

    site_id: str
    folder: Path
    images: int
    counts: dict[str, int]
    skipped: bool


PairsResult = SitesRun[SitePairs]


def select_pairs(views: list[CameraView], config: PairsConfig) -> tuple[dict[Pair, str], dict[str, object]]:
    """Sequential pairs, each repeated view with the one it repeats, then HSP pairs among the rest of the
    views that repeat nothing; the HSP funnel (with the number of repeated views) for the report."""
    pairs = sequential_pairs(views, config)
    repeats = repeated_views(views, config)
    for pair, reason in repeat_pairs(repeats).items():
        pairs.setdefault(pair, reason)
    spatial, stats = spatial_pairs(views, config, exclude=set(pairs), skip=set(repeats))
    pairs.update(spatial)
    return pairs, {**asdict(stats), "repeated_views": len(repeats)}


def _counts(pairs: dict[Pair, str], n_images: int) -> dict[str, int]:
    counts = {reason: 0 for reason in PAIR_REASONS}
    for reason in pairs.values():
        counts[reason] += 1
    return {"exhaustive": n_images * (n_images - 1) // 2, **counts, "total": len(pairs)}


def run(
    config: PairsConfig,
    dataset_root: Path,
    workspace: Path | None = None,
    *,
    overwrite: bool = False,
) -> PairsResult:
    """Write `pairs/<site_id>/pairs.{txt,json}` for every site in `sites/index.json` (after `cama sites`)."""
    started = time.perf_counter()
    workspace = Path(workspace) if workspace is not None else default_workspace(Path(dataset_root))
    index = read_sites_index(sites_index_path(workspace))
    dataset = None
    done: list[SitePairs] = []
    for site in index["sites"]:
        site_id = site["site_id"]
        manifest_path = site_manifest_path(workspace, site_id)
        folder = pairs_dir(workspace, site_id)
        digest = fingerprint(code_version("cama_pipeline.pairs"), asdict(config), file_stats([manifest_path]))
        if not overwrite and stored_fingerprint(folder / "pairs.json") == digest:
            stored = read_pairs(folder)
            done.append(SitePairs(site_id, folder, stored["images"], stored["counts"], skipped=True))
            continue
        if dataset is None:
            dataset = load_dataset(Path(dataset_root), check_files=False)  # poses only: no image is read
        views = site_views(dataset, read_site_manifest(manifest_path))
        pairs, funnel = select_pairs(views, config)
        rows = [(views[i].name, views[j].name, reason) for (i, j), reason in sorted(pairs.items())]
        counts = _counts(pairs, len(views))
        write_pairs(
            folder,
            site_id=site_id,
            digest=digest,
            config=config,
            images=len(views),
            counts=counts,
            funnel=funnel,
            pairs=rows,
        )
        logger.info("site %s: %d images, pairs %s", site_id, len(views), counts)
        done.append(SitePairs(site_id, folder, len(views), counts, skipped=False))
    return PairsResult(workspace, tuple(done), time.perf_counter() - started)
