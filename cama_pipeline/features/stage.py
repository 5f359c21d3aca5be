"""The features stage: masked features of every keyframe image into the site's COLMAP database
(`cama_pipeline.features.database`), then matching with geometric verification on the pairs chosen by
`cama pairs`; its report is `features.json` (`cama_pipeline.features.io`).

A rerun whose fingerprint and database are unchanged does nothing (it does not even open the database, so
later stages keyed on it stay up to date). Otherwise the database is reused when its features were extracted
with the same settings, masks and code (`extraction.json` records that): images already in it are not
extracted again, matched pairs are not matched again, and the matches of pairs the list no longer holds are
deleted ("pairs_pruned"), so the database matches exactly the listed pairs. Features from other settings or
masks (a new segmenter's, say) are dropped and every image is extracted again. A change of extractor needs
`--overwrite`.
"""

import logging
import multiprocessing
import statistics
import time
from collections.abc import Iterator
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from cama_pipeline.cameras import CameraView, site_views
from cama_pipeline.code_version import code_version
from cama_pipeline.data import Dataset, MaskChoice, load_dataset, mask_roots, masks_fingerprint
from cama_pipeline.features.config import FeaturesConfig
from cama_pipeline.features.database import FeatureStore, open_database, prune_unlisted, verified_pairs
from cama_pipeline.features.interface import FeatureExtractor, Features, PairMatcher
from cama_pipeline.features.io import read_report, write_report
from cama_pipeline.features.masks import ego_estimates, feature_block, keypoints_allowed, masks_label_ego
from cama_pipeline.features.matching import BlasMatcher
from cama_pipeline.features.sift import ColmapMatcher, SiftExtractor
from cama_pipeline.fingerprints import file_stats, fingerprint, is_up_to_date
from cama_pipeline.io import WorkspaceError, atomic_write_json, read_json
from cama_pipeline.progress import StageProgress
from cama_pipeline.results import ItemResult, StageResult
from cama_pipeline.semantics import Semantic
from cama_pipeline.site.io import read_site_ids, read_site_manifest, read_site_scenes
from cama_pipeline.workspace import Workspace

logger = logging.getLogger(__name__)


EgoMasks = dict[tuple[str, str], np.ndarray]
"""Estimated ego body by (scene, channel), for the cameras whose masks label none."""


def image_features(
    dataset: Dataset,
    view: CameraView,
    extractor: FeatureExtractor,
    config: FeaturesConfig,
    ego: np.ndarray | None = None,
) -> tuple[Features, int]:
    """The view's features with those on the ego body and vehicles removed, and how many were removed; `ego`
    is the estimated ego body, used when the view's mask labels none."""
    image = dataset.image(view.token)
    gray = cv2.cvtColor(image.load_rgb(), cv2.COLOR_RGB2GRAY)
    features = extractor.extract(gray)
    semantic = image.load_semantic() if image.semantic_mask_path is not None else None
    blocked = feature_block(semantic, ego, config.masked_classes, config.mask_dilation_px)
    if blocked is None:
        logger.warning("%s has no semantic mask and no ego estimate: its features are not masked", view.name)
        return features, 0
    keep = keypoints_allowed(features.keypoints[:, :2], blocked)
    return features.subset(keep), int((~keep).sum())


MIN_IMAGES_PER_PROCESS = 16
"""Extraction runs in worker processes only when each gets at least this many images (a process takes about a
second to start and import pycolmap)."""
_worker_state: tuple[Dataset, FeatureExtractor, FeaturesConfig, EgoMasks] | None = None


def _start_worker(
    root: Path,
    version: str,
    roots: tuple[Path, ...],
    scenes: tuple[str, ...],
    extractor: FeatureExtractor,
    config: FeaturesConfig,
    ego: EgoMasks,
) -> None:
    """Worker-process set-up: its own data set tables of the scenes it works on (masks from the same roots) and
    extractor."""
    global _worker_state
    dataset = load_dataset(root, version, check_files=False, mask_roots=roots, scenes=scenes)
    _worker_state = (dataset, extractor, config, ego)


def _extract_in_worker(view: CameraView) -> tuple[Features, int]:
    if _worker_state is None:
        raise RuntimeError("extraction worker used before _start_worker")
    dataset, extractor, config, ego = _worker_state
    return image_features(dataset, view, extractor, config, ego.get((view.scene, view.channel)))


def _extracted(
    dataset: Dataset,
    todo: list[CameraView],
    extractor: FeatureExtractor,
    config: FeaturesConfig,
    ego: EgoMasks,
) -> Iterator[tuple[Features, int]]:
    """Masked features of `todo` in order: in `config.num_threads` processes when there are enough images
    (pycolmap's SIFT holds the GIL, so threads do not help), else here."""
    workers = min(config.num_threads, len(todo) // MIN_IMAGES_PER_PROCESS)
    if workers < 2:
        for view in todo:
            yield image_features(dataset, view, extractor, config, ego.get((view.scene, view.channel)))
        return
    scenes = tuple(sorted({view.scene for view in todo}))
    setup = (dataset.root, dataset.version, dataset.mask_roots, scenes, extractor, config, ego)
    context = multiprocessing.get_context("spawn")  # forking a process that may hold threads is unsafe
    with ProcessPoolExecutor(workers, mp_context=context, initializer=_start_worker, initargs=setup) as pool:
        yield from pool.map(_extract_in_worker, todo, chunksize=4)


def site_ego_masks(dataset: Dataset, views: list[CameraView], config: FeaturesConfig) -> EgoMasks:
    """The ego body estimated per scene and camera when the site's masks label none (`FeaturesConfig.ego`)."""
    if not config.ego_from_clip or int(Semantic.EGO) not in config.masked_classes:
        return {}
    if masks_label_ego(dataset, views):
        return {}
    estimates = ego_estimates(dataset, views, config.ego)
    logger.info(
        "the masks label no ego body: estimated from the clips for %d of %d cameras",
        sum(bool(mask.any()) for mask in estimates.values()),
        len({(view.scene, view.channel) for view in views}),
    )
    return estimates


def extract_missing(
    dataset: Dataset,
    views: list[CameraView],
    store: FeatureStore,
    extractor: FeatureExtractor,
    config: FeaturesConfig,
    ego: EgoMasks | None = None,
) -> dict[str, dict[str, int | None]]:
    """Extract the views the database lacks into it, with a progress bar; counts per newly extracted image.
    `ego`: the estimated ego bodies (`site_ego_masks` of the views to extract when None). A multi-process run
    needs a picklable extractor."""
    counts: dict[str, dict[str, int | None]] = {}
    todo = [view for view in views if not store.has(view.name)]
    if ego is None:
        ego = site_ego_masks(dataset, todo, config) if todo else {}
    with StageProgress("features", logger=logger, transient=True) as progress:
        task = progress.add_task("extract", total=len(todo))
        extracted = _extracted(dataset, todo, extractor, config, ego)
        for view, (features, masked) in zip(todo, extracted, strict=True):
            store.add(view, features)
            counts[view.name] = {"features": len(features.keypoints), "masked": masked}
            progress.advance(task)
    return counts


def _previous_report(path: Path, extractor: FeatureExtractor) -> dict[str, Any]:
    """The stored report (empty when none); WorkspaceError when it was made by another extractor."""
    if not path.is_file():
        return {}
    report = read_report(path)
    if report.get("extractor") != extractor.name:
        raise WorkspaceError(
            f"{path}: database made with extractor {report.get('extractor')!r}, not {extractor.name!r}; "
            "rerun with --overwrite"
        )
    return report


EXTRACTION_SCHEMA = "cama.features-extraction/1"


def drop_stale_features(database: Path, record: Path, extraction: str) -> bool:
    """Remove the database when its features were extracted with other settings, masks or code, or when it is
    not recorded with what (`record` holds the extraction fingerprint), so that every image is extracted again:
    reusing them would keep features from masks or settings the run no longer has. Then record this run's
    extraction, before it extracts, so that an interrupted run resumes. Whether a database was removed."""
    try:
        recorded = read_json(record, EXTRACTION_SCHEMA, "cama features")
    except (FileNotFoundError, WorkspaceError):  # none, or unreadable: not known what the features came from
        recorded = {}
    stale = database.is_file() and recorded.get("extraction") != extraction
    if stale:
        logger.info(
            "%s: extracted with other settings, masks or code; extracting every image again", database
        )
        for leftover in (database, *(database.with_name(database.name + s) for s in ("-shm", "-wal"))):
            leftover.unlink(missing_ok=True)
    record.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_json(record, {"schema": EXTRACTION_SCHEMA, "extraction": extraction}, indent=1)
    return stale


def run_site(
    dataset: Dataset,
    workspace: Workspace,
    site_id: str,
    config: FeaturesConfig,
    *,
    extractor: FeatureExtractor,
    matcher: PairMatcher,
    masks: MaskChoice | str = "auto",
    overwrite: bool = False,
) -> ItemResult:
    """Extract and match one site (see the module docstring); its item: the site's features folder and report.
    `masks` is the choice the data set's mask roots came from (`dataset.mask_roots`), for the fingerprint."""
    folder = workspace.features_dir(site_id)
    database, report_path = workspace.features_db(site_id), workspace.features_report(site_id)
    pairs_file = workspace.pairs_txt(site_id)
    if not pairs_file.is_file():
        raise FileNotFoundError(f"{pairs_file}: not found; run `cama pairs` first")
    if overwrite:
        database.unlink(missing_ok=True)
        report_path.unlink(missing_ok=True)
    previous = _previous_report(report_path, extractor)
    manifest_path = workspace.site_manifest(site_id)
    extraction = fingerprint(
        code_version("cama_pipeline.features"),
        asdict(config),
        extractor.name,
        masks_fingerprint(masks, dataset.mask_roots, dataset.root),
    )
    digest = fingerprint(extraction, matcher.name, file_stats([manifest_path, pairs_file]))
    size = database.stat().st_size if database.is_file() else None
    if size is not None and is_up_to_date(report_path, digest) and previous.get("database_bytes") == size:
        logger.info("features of %s up to date", site_id)
        return ItemResult(site_id, folder, previous, skipped=True)
    if drop_stale_features(database, workspace.features_extraction(site_id), extraction):
        previous = {}
    views = site_views(dataset, read_site_manifest(manifest_path))
    started = time.perf_counter()
    with open_database(database) as db:
        store = FeatureStore(db)
        todo = [view for view in views if not store.has(view.name)]
        ego = site_ego_masks(dataset, todo, config) if todo else {}
        counts = {
            **previous.get("images", {}),
            **extract_missing(dataset, views, store, extractor, config, ego),
        }
        for view in views:  # extracted by an interrupted run that wrote no report: masked pixels unknown
            if view.name not in counts:
                counts[view.name] = {"features": store.keypoint_count(view.name), "masked": None}
    extracted = time.perf_counter()
    matcher.match(database, pairs_file)
    listed = {frozenset(line.split()) for line in pairs_file.read_text().splitlines() if line.strip()}
    with open_database(database) as db:
        pruned = prune_unlisted(db, listed)
        verified = verified_pairs(db)
    if pruned:
        logger.info("dropped the matches of %d pairs no longer listed in %s", pruned, pairs_file)
    low = sorted(name for name, c in counts.items() if c["features"] < config.min_features_warning)
    if low:
        logger.warning(
            "%d image(s) with under %d features, e.g. %s", len(low), config.min_features_warning, low[:3]
        )
    report = {
        "site_id": site_id,
        "extractor": extractor.name,
        "matcher": matcher.name,
        "images": counts,
        "low_feature_images": low,
        "masks": [list(part) for part in masks_fingerprint(masks, dataset.mask_roots, dataset.root)],
        "ego_estimated": {
            **previous.get("ego_estimated", {}),
            **{f"{scene}/{channel}": float(mask.mean()) for (scene, channel), mask in ego.items()},
        },
        "pairs_listed": len(listed),
        "pairs_pruned": pruned,
        "pairs_verified": len(verified),
        "median_inliers": statistics.median(verified.values()) if verified else 0,
        "seconds": {"extract": extracted - started, "match": time.perf_counter() - extracted},
    }
    report["fingerprint"] = digest
    report["database_bytes"] = database.stat().st_size
    report = write_report(report_path, report)
    return ItemResult(site_id, folder, report, skipped=False)


def run(
    config: FeaturesConfig,
    dataset_root: Path,
    workspace: Path | Workspace | None = None,
    *,
    extractor: FeatureExtractor | None = None,
    matcher: PairMatcher | None = None,
    masks: MaskChoice | str = "auto",
    overwrite: bool = False,
) -> StageResult:
    """Features and matches for every site of the workspace (after `cama pairs`); SIFT and the matcher named by
    the config unless another extractor/matcher pair is given; vehicles and the ego body masked by the masks of
    `masks` (`cama_pipeline.data.masks`)."""
    started = time.perf_counter()
    ws = Workspace.resolve(workspace, Path(dataset_root))
    site_ids = read_site_ids(ws.sites_index())
    roots = mask_roots(masks, Path(dataset_root), ws)
    dataset = load_dataset(Path(dataset_root), mask_roots=roots, scenes=read_site_scenes(ws.sites_index()))
    extractor = extractor or SiftExtractor(config)
    matcher = matcher or (BlasMatcher(config) if config.matcher == "blas" else ColmapMatcher(config))
    items = tuple(
        run_site(
            dataset,
            ws,
            site_id,
            config,
            extractor=extractor,
            matcher=matcher,
            masks=masks,
            overwrite=overwrite,
        )
        for site_id in site_ids
    )
    return StageResult("features", ws, items, time.perf_counter() - started)
