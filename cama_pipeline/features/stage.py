"""The features stage: masked features of every keyframe image into the site's COLMAP database, then
matching with geometric verification on the pairs chosen by `cama pairs`.

    <workspace>/features/<site_id>/database.db     COLMAP database (cameras, images, keypoints, matches)
    <workspace>/features/<site_id>/features.json   schema "cama.features/1": extractor, matcher, per-image
        counts {"name": {"features", "masked" (null when an interrupted run extracted it)}},
        "low_feature_images" [name], "pairs_listed", "pairs_pruned", "pairs_verified", "median_inliers",
        "seconds": {"extract", "match"}
    "fingerprint": code, config, extractor, matcher, manifest and pair list; "database_bytes": the database's size
        as this stage left it (not its mtime: merely reading a SQLite database can touch that).
A rerun whose fingerprint and database are unchanged does nothing (it does not even open the database, so
later stages keyed on it stay up to date). Otherwise the database is reused: images already in it are not
extracted again, matched pairs are not matched again, and the matches of pairs the list no longer holds are
deleted ("pairs_pruned"), so the database matches exactly the listed pairs. A change of extractor needs
`--overwrite`.
"""

import logging
import multiprocessing
import statistics
import time
from collections.abc import Iterator
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import cv2

from cama_pipeline.cameras import CameraView, site_views
from cama_pipeline.code_version import code_version
from cama_pipeline.data import Dataset, load_dataset
from cama_pipeline.features.config import FeaturesConfig
from cama_pipeline.features.database import FeatureStore, open_database, prune_unlisted, verified_pairs
from cama_pipeline.features.interface import FeatureExtractor, Features, PairMatcher
from cama_pipeline.features.masks import blocked_pixels, keypoints_allowed
from cama_pipeline.features.matching import BlasMatcher
from cama_pipeline.features.sift import ColmapMatcher, SiftExtractor
from cama_pipeline.io import atomic_write_json
from cama_pipeline.pairs.io import pairs_dir
from cama_pipeline.progress import StageProgress
from cama_pipeline.site.workspace import (
    WorkspaceError,
    default_workspace,
    file_stats,
    fingerprint,
    read_json,
    read_site_manifest,
    read_sites_index,
    site_manifest_path,
    sites_index_path,
)

logger = logging.getLogger(__name__)
FEATURES_SCHEMA = "cama.features/1"


@dataclass(frozen=True)
class SiteFeatures:
    """One site's database and what went into it."""

    site_id: str
    database: Path
    report: dict[str, Any]


def features_dir(workspace: Path, site_id: str) -> Path:
    """`<workspace>/features/<site_id>/`."""
    return Path(workspace) / "features" / site_id


def image_features(
    dataset: Dataset, view: CameraView, extractor: FeatureExtractor, config: FeaturesConfig
) -> tuple[Features, int]:
    """The view's features with those on the ego body and vehicles removed, and how many were removed."""
    image = dataset.image(view.token)
    gray = cv2.cvtColor(image.load_rgb(), cv2.COLOR_RGB2GRAY)
    features = extractor.extract(gray)
    if image.semantic_mask_path is None:
        logger.warning("%s has no semantic mask: its features are not masked", view.name)
        return features, 0
    blocked = blocked_pixels(image.load_semantic(), config.masked_classes, config.mask_dilation_px)
    keep = keypoints_allowed(features.keypoints[:, :2], blocked)
    return features.subset(keep), int((~keep).sum())


MIN_IMAGES_PER_PROCESS = 16
"""Extraction runs in worker processes only when each gets at least this many images (a process takes about a
second to start and import pycolmap)."""
_worker_state: tuple[Dataset, FeatureExtractor, FeaturesConfig] | None = None


def _start_worker(root: Path, version: str, extractor: FeatureExtractor, config: FeaturesConfig) -> None:
    """Worker-process set-up: its own data set tables and extractor (unpickled from the parent's)."""
    global _worker_state
    _worker_state = (load_dataset(root, version, check_files=False), extractor, config)


def _extract_in_worker(view: CameraView) -> tuple[Features, int]:
    if _worker_state is None:
        raise RuntimeError("extraction worker used before _start_worker")
    return image_features(_worker_state[0], view, _worker_state[1], _worker_state[2])


def _extracted(
    dataset: Dataset, todo: list[CameraView], extractor: FeatureExtractor, config: FeaturesConfig
) -> Iterator[tuple[Features, int]]:
    """Masked features of `todo` in order: in `config.num_threads` processes when there are enough images
    (pycolmap's SIFT holds the GIL, so threads do not help), else here."""
    workers = min(config.num_threads, len(todo) // MIN_IMAGES_PER_PROCESS)
    if workers < 2:
        yield from (image_features(dataset, view, extractor, config) for view in todo)
        return
    setup = (dataset.root, dataset.version, extractor, config)
    context = multiprocessing.get_context("spawn")  # forking a process that may hold threads is unsafe
    with ProcessPoolExecutor(workers, mp_context=context, initializer=_start_worker, initargs=setup) as pool:
        yield from pool.map(_extract_in_worker, todo, chunksize=4)


def extract_missing(
    dataset: Dataset,
    views: list[CameraView],
    store: FeatureStore,
    extractor: FeatureExtractor,
    config: FeaturesConfig,
) -> dict[str, dict[str, int | None]]:
    """Extract the views the database lacks into it, with a progress bar; counts per newly extracted image.
    A multi-process run needs a picklable extractor."""
    counts: dict[str, dict[str, int | None]] = {}
    todo = [view for view in views if not store.has(view.name)]
    with StageProgress("features", logger=logger, transient=True) as progress:
        task = progress.add_task("extract", total=len(todo))
        for view, (features, masked) in zip(todo, _extracted(dataset, todo, extractor, config), strict=True):
            store.add(view, features)
            counts[view.name] = {"features": len(features.keypoints), "masked": masked}
            progress.advance(task)
    return counts


def _previous_report(path: Path, extractor: FeatureExtractor) -> dict[str, Any]:
    """The stored report (empty when none); WorkspaceError when it was made by another extractor."""
    if not path.is_file():
        return {}
    report = read_json(path, FEATURES_SCHEMA, "cama features")
    if report.get("extractor") != extractor.name:
        raise WorkspaceError(
            f"{path}: database made with extractor {report.get('extractor')!r}, not {extractor.name!r}; "
            "rerun with --overwrite"
        )
    return report


def run_site(
    dataset: Dataset,
    workspace: Path,
    site_id: str,
    config: FeaturesConfig,
    *,
    extractor: FeatureExtractor,
    matcher: PairMatcher,
    overwrite: bool = False,
) -> SiteFeatures:
    """Extract and match one site (see the module docstring for the files)."""
    folder = features_dir(workspace, site_id)
    database, report_path = folder / "database.db", folder / "features.json"
    pairs_file = pairs_dir(workspace, site_id) / "pairs.txt"
    if not pairs_file.is_file():
        raise FileNotFoundError(f"{pairs_file}: not found; run `cama pairs` first")
    if overwrite:
        database.unlink(missing_ok=True)
        report_path.unlink(missing_ok=True)
    previous = _previous_report(report_path, extractor)
    manifest_path = site_manifest_path(workspace, site_id)
    digest = fingerprint(
        code_version("cama_pipeline.features"),
        asdict(config),
        extractor.name,
        matcher.name,
        file_stats([manifest_path, pairs_file]),
    )
    size = database.stat().st_size if database.is_file() else None
    if size is not None and previous.get("fingerprint") == digest and previous.get("database_bytes") == size:
        logger.info("features of %s up to date", site_id)
        return SiteFeatures(site_id, database, previous)
    views = site_views(dataset, read_site_manifest(manifest_path))
    started = time.perf_counter()
    with open_database(database) as db:
        store = FeatureStore(db)
        counts = {
            **previous.get("images", {}),
            **extract_missing(dataset, views, store, extractor, config),
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
        "schema": FEATURES_SCHEMA,
        "site_id": site_id,
        "extractor": extractor.name,
        "matcher": matcher.name,
        "images": counts,
        "low_feature_images": low,
        "pairs_listed": len(listed),
        "pairs_pruned": pruned,
        "pairs_verified": len(verified),
        "median_inliers": statistics.median(verified.values()) if verified else 0,
        "seconds": {"extract": extracted - started, "match": time.perf_counter() - extracted},
    }
    report["fingerprint"] = digest
    report["database_bytes"] = database.stat().st_size
    atomic_write_json(report_path, report, indent=1)
    return SiteFeatures(site_id, database, report)


def run(
    config: FeaturesConfig,
    dataset_root: Path,
    workspace: Path | None = None,
    *,
    extractor: FeatureExtractor | None = None,
    matcher: PairMatcher | None = None,
    overwrite: bool = False,
) -> list[SiteFeatures]:
    """Features and matches for every site of the workspace (after `cama pairs`); SIFT and the matcher named by
    the config unless another extractor/matcher pair is given."""
    workspace = Path(workspace) if workspace is not None else default_workspace(Path(dataset_root))
    index = read_sites_index(sites_index_path(workspace))
    dataset = load_dataset(Path(dataset_root))
    extractor = extractor or SiftExtractor(config)
    matcher = matcher or (BlasMatcher(config) if config.matcher == "blas" else ColmapMatcher(config))
    return [
        run_site(
            dataset,
            workspace,
            site["site_id"],
            config,
            extractor=extractor,
            matcher=matcher,
            overwrite=overwrite,
        )
        for site in index["sites"]
    ]
