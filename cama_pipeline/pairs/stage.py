"""The pairs stage: for every site of the workspace, sequential + HSP pairs of its keyframe images."""

import logging
import time
from collections.abc import Mapping
from dataclasses import asdict
from pathlib import Path

from cama_pipeline.cameras import CameraView, site_views
from cama_pipeline.code_version import code_version
from cama_pipeline.data import load_dataset
from cama_pipeline.fingerprints import file_stats, fingerprint, is_up_to_date
from cama_pipeline.pairs.config import PairsConfig
from cama_pipeline.pairs.hsp import spatial_pairs
from cama_pipeline.pairs.io import PAIR_REASONS, read_pairs, write_pairs
from cama_pipeline.pairs.repeats import repeat_pairs, repeated_views
from cama_pipeline.pairs.sequential import Pair, sequential_pairs
from cama_pipeline.results import ItemResult, StageResult
from cama_pipeline.site.heights import keyframe_track, level_groups
from cama_pipeline.site.io import read_site_ids, read_site_manifest, read_site_scenes
from cama_pipeline.wigo.stage import free_height_scenes
from cama_pipeline.workspace import Workspace

logger = logging.getLogger(__name__)
REPORT_FIELDS = ("images", "counts", "hsp_funnel")
"""The parts of pairs.json a run reports per site (all but the pairs themselves)."""


def select_pairs(
    views: list[CameraView], config: PairsConfig, height_offsets: Mapping[str, float] | None = None
) -> tuple[dict[Pair, str], dict[str, object]]:
    """Sequential pairs, each repeated view with the one it repeats, then HSP pairs among the rest of the
    views that repeat nothing (the height rule on the heights moved by `height_offsets`, metres per scene); the
    HSP funnel (with the number of repeated views and the offsets) for the report."""
    pairs = sequential_pairs(views, config)
    repeats = repeated_views(views, config)
    for pair, reason in repeat_pairs(repeats).items():
        pairs.setdefault(pair, reason)
    spatial, stats = spatial_pairs(
        views, config, exclude=set(pairs), skip=set(repeats), height_offsets=height_offsets
    )
    pairs.update(spatial)
    offsets = dict(height_offsets or {})
    return pairs, {**asdict(stats), "repeated_views": len(repeats), "free_height_offsets_m": offsets}


def free_height_offsets(
    workspace: Workspace, views: list[CameraView], config: PairsConfig
) -> dict[str, float]:
    """Per scene whose heights WIGO left free and that could be tied, the metres that bring it to the road the
    other scenes drove (`cama_pipeline.site.heights`); none when `config.level_free_heights` is off."""
    scenes = sorted({view.scene for view in views})
    free = free_height_scenes(workspace, scenes) if config.level_free_heights else frozenset()
    if not free:
        return {}
    tracks = {scene: keyframe_track([v for v in views if v.scene == scene]) for scene in scenes}
    ties = level_groups([[scene] for scene in scenes], tracks, free)
    return {scene: tie.offset_m for scene, tie in ties.items() if tie.tied}


def _counts(pairs: dict[Pair, str], n_images: int) -> dict[str, int]:
    counts = {reason: 0 for reason in PAIR_REASONS}
    for reason in pairs.values():
        counts[reason] += 1
    return {"exhaustive": n_images * (n_images - 1) // 2, **counts, "total": len(pairs)}


def run(
    config: PairsConfig,
    dataset_root: Path,
    workspace: Path | Workspace | None = None,
    *,
    overwrite: bool = False,
) -> StageResult:
    """Write `pairs/<site_id>/pairs.{txt,json}` for every site in `sites/index.json` (after `cama sites`); one
    item per site, its report pairs.json's images, counts and HSP funnel."""
    started = time.perf_counter()
    ws = Workspace.resolve(workspace, Path(dataset_root))
    dataset = None
    done: list[ItemResult] = []
    for site_id in read_site_ids(ws.sites_index()):
        manifest_path = ws.site_manifest(site_id)
        folder, report_path = ws.pairs_dir(site_id), ws.pairs_json(site_id)
        digest = fingerprint(code_version("cama_pipeline.pairs"), asdict(config), file_stats([manifest_path]))
        if not overwrite and is_up_to_date(report_path, digest):
            stored = read_pairs(report_path)
            done.append(ItemResult(site_id, folder, {k: stored[k] for k in REPORT_FIELDS}, skipped=True))
            continue
        if dataset is None:
            # poses only: no image is read
            dataset = load_dataset(
                Path(dataset_root), check_files=False, scenes=read_site_scenes(ws.sites_index())
            )
        views = site_views(dataset, read_site_manifest(manifest_path))
        pairs, funnel = select_pairs(views, config, free_height_offsets(ws, views, config))
        rows = [(views[i].name, views[j].name, reason) for (i, j), reason in sorted(pairs.items())]
        counts = _counts(pairs, len(views))
        write_pairs(
            ws.pairs_txt(site_id),
            report_path,
            site_id=site_id,
            digest=digest,
            config=config,
            images=len(views),
            counts=counts,
            funnel=funnel,
            pairs=rows,
        )
        logger.info("site %s: %d images, pairs %s", site_id, len(views), counts)
        report = {"images": len(views), "counts": counts, "hsp_funnel": funnel}
        done.append(ItemResult(site_id, folder, report, skipped=False))
    return StageResult("pairs", ws, tuple(done), time.perf_counter() - started)
