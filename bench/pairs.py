"""Pair-selection benchmark: exhaustive vs sequential vs sequential + HSP on a synthetic site.

For the keyframe images of each site (after wigo -> keyframes -> sites, run here into a temporary workspace):
  pairs      how many pairs each strategy selects;
  recall     the share of truly co-visible pairs each strategy selects. Ground truth (true poses, true elevation
             raster, `cama_pipeline/evaluate/covisibility.py`): C[a, b] = share of camera a's ground within 25 m
             that camera b sees. Strongly co-visible: min(C[a, b], C[b, a]) >= 0.5 (each sees half the other's
             ground); also reported for >= 0.3 and for max(C) >= 0.5. A repeated view (`pairs/repeats.py`, a
             stationary clip's frames) stands for the view it repeats: a true pair counts as selected when the
             pair of the views they repeat is (or both repeat one view), since the repeat pairs chain them;
  matching   SIFT on the images of a random sample of each strategy's pairs, then matching and geometric
             verification of that sample with each matcher ("blas": the default, one matrix product per pair;
             "colmap": COLMAP's CPU matcher, the baseline): seconds per pair (so the estimated total for every pair
             of the strategy, exhaustive included, which is too slow to run whole), CPU seconds per pair (the
             machine may be shared) and the share of sampled pairs that verify; totals for all of a strategy's
             pairs are `estimated_matching_seconds` (wall) and `estimated_matching_cpu_seconds`. A site generated
             without images (`cama synth --no-images`) cannot be matched: its matching time is an ESTIMATE,
             each strategy's pairs times the CPU seconds per pair of the same strategy measured on a site with
             images (of this run, or else kept in the output file), marked `"measured": false` with its basis,
             with CPU totals only.
Ratios (HSP / exhaustive pairs and matching CPU and wall time, blas / colmap matching time) come from the same run.

Usage: .venv/bin/python bench/pairs.py [--site data/synthetic/default] [--workspace W] [--sample 150]
With --workspace, the site's existing wigo -> keyframes -> sites outputs are read (never written) instead of
being recomputed into a temporary workspace.
Prints the figures and writes them to bench/results/pairs.json: one entry per site folder given, merged into
the entries the file already holds for other sites (kept only when they were made with the same pairs config),
with the command that made each entry under "commands".
"""

import argparse
import json
import logging
import platform
import random
import shutil
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from cama_pipeline.bev import read_bev
from cama_pipeline.cameras import CameraView, site_views
from cama_pipeline.data import load_dataset
from cama_pipeline.evaluate.covisibility import ElevationSurface, covisibility_matrix
from cama_pipeline.evaluate.inputs import load_true_poses
from cama_pipeline.features.config import FeaturesConfig
from cama_pipeline.features.database import FeatureStore, open_database, verified_pairs
from cama_pipeline.features.interface import PairMatcher
from cama_pipeline.features.matching import BlasMatcher
from cama_pipeline.features.sift import ColmapMatcher, SiftExtractor
from cama_pipeline.features.stage import extract_missing
from cama_pipeline.keyframes import KeyframeConfig
from cama_pipeline.keyframes import run as run_keyframes
from cama_pipeline.pairs.config import PairsConfig
from cama_pipeline.pairs.repeats import repeated_views
from cama_pipeline.pairs.sequential import Pair, sequential_pairs
from cama_pipeline.pairs.stage import select_pairs
from cama_pipeline.site.config import SiteConfig
from cama_pipeline.site.io import read_site_ids, read_site_manifest
from cama_pipeline.site.stage import run as run_sites
from cama_pipeline.wigo import WigoConfig
from cama_pipeline.wigo import run as run_wigo
from cama_pipeline.workspace import Workspace

RESULTS = Path(__file__).parent / "results"
STRATEGIES = ("exhaustive", "sequential", "sequential+hsp")
MATCHERS = ("blas", "colmap")
STRONG = {"mutual>=0.5": ("min", 0.5), "mutual>=0.3": ("min", 0.3), "max>=0.5": ("max", 0.5)}
logger = logging.getLogger("bench.pairs")


def true_views(views: list[CameraView], site: Path) -> list[CameraView]:
    """The same cameras posed by the ground truth."""
    truth = load_true_poses(site / "ground_truth" / "poses.json")
    return [replace(view, world_from_ego=truth[view.token].matrix()) for view in views]


def surface(site: Path) -> ElevationSurface:
    """The ground-truth elevation raster."""
    bev = read_bev(site / "ground_truth" / "bev", ["elevation"])
    geo = bev.georeference
    return ElevationSurface(bev.require("elevation"), geo.origin_xy, geo.resolution)


def recalled(truth: set[Pair], selected: set[Pair], repeats: dict[int, int]) -> int:
    """True pairs the selection covers, directly or through the views they repeat."""

    def stands_for(index: int) -> int:
        return repeats.get(index, index)

    def covered(a: int, b: int) -> bool:
        x, y = sorted((stands_for(a), stands_for(b)))
        return (a, b) in selected or x == y or (x, y) in selected

    return sum(covered(a, b) for a, b in truth)


def strong_sets(covisibility: np.ndarray) -> dict[str, set[Pair]]:
    """Truly co-visible pairs under each definition."""
    upper = np.triu(np.ones_like(covisibility, dtype=bool), 1)
    sets = {}
    for name, (how, threshold) in STRONG.items():
        both = np.minimum if how == "min" else np.maximum
        a, b = np.nonzero(upper & (both(covisibility, covisibility.T) >= threshold))
        sets[name] = {(int(i), int(j)) for i, j in zip(a, b, strict=True)}
    return sets


def time_matching(
    dataset: Any, views: list[CameraView], pairs: list[Pair], folder: Path, config: FeaturesConfig
) -> dict[str, Any]:
    """Extract the sampled pairs' images, then match the sample with each matcher on its own copy of the
    database: seconds (wall and CPU) per image and per pair, verified share and median inliers."""
    used = [views[i] for i in sorted({i for pair in pairs for i in pair})]
    extracted_db = folder / "extracted.db"
    started = time.perf_counter()
    with open_database(extracted_db) as db:
        extract_missing(dataset, used, FeatureStore(db), SiftExtractor(config), config)
    out: dict[str, Any] = {
        "sampled_pairs": len(pairs),
        "seconds_per_image": (time.perf_counter() - started) / max(len(used), 1),
    }
    pairs_file = folder / "pairs.txt"
    pairs_file.write_text("".join(f"{views[i].name} {views[j].name}\n" for i, j in pairs))
    matchers: dict[str, PairMatcher] = {"blas": BlasMatcher(config), "colmap": ColmapMatcher(config)}
    for name, matcher in matchers.items():
        database = folder / f"{name}.db"
        shutil.copy(extracted_db, database)
        wall, cpu = time.perf_counter(), time.process_time()
        matcher.match(database, pairs_file)
        wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
        with open_database(database) as db:
            verified = verified_pairs(db)
        out[name] = {
            "seconds_per_pair": wall / max(len(pairs), 1),
            "cpu_seconds_per_pair": cpu / max(len(pairs), 1),
            "verified_share": len(verified) / max(len(pairs), 1),
            "median_inliers": float(np.median(list(verified.values()))) if verified else 0.0,
        }
    return out


def has_images(dataset_root: Path, views: list[CameraView]) -> bool:
    """Whether every view's image file exists (not so on a site generated with `cama synth --no-images`)."""
    return all((dataset_root / view.name).is_file() for view in views)


def measured_reference(sites: dict[str, dict[str, Any]]) -> dict[str, Any] | None:
    """CPU seconds per pair of each strategy and matcher on the first site entry whose matching was measured."""
    for site, entries in sites.items():
        for site_id, report in entries.items():
            if all("blas" in report[name]["matching"] for name in STRATEGIES):
                cpu = {
                    name: {m: report[name]["matching"][m]["cpu_seconds_per_pair"] for m in MATCHERS}
                    for name in STRATEGIES
                }
                return {"source": f"{site} {site_id}", "cpu_seconds_per_pair": cpu}
    return None


def estimated_matching(strategy: str, count: int, reference: dict[str, Any]) -> dict[str, Any]:
    """The matching entry of a strategy that could not be matched (no images): an estimate, labelled as one."""
    cpu = reference["cpu_seconds_per_pair"][strategy]
    return {
        "measured": False,
        "estimate": f"NOT MEASURED: {count} pairs x the CPU seconds per pair of {strategy!r} measured on "
        f"{reference['source']}; the site has no images (larger images or denser features would cost more)",
        "reference_cpu_seconds_per_pair": cpu,
    }


def bench_site(
    site: Path, sample: int, seed: int, sites_from: Path | None, reference: dict[str, Any] | None
) -> dict[str, Any]:
    """All figures of one generated site (its sites read from `sites_from` when given, else computed); matching
    is estimated from `reference` (see `measured_reference`) when the site has no images."""
    dataset_root = site / "nuscenes"
    dataset = load_dataset(dataset_root, check_files=False)
    out: dict[str, Any] = {}
    with tempfile.TemporaryDirectory(prefix="cama-bench-pairs-") as tmp:
        workspace = Path(tmp)
        if sites_from is None:
            run_wigo(WigoConfig(), dataset_root, workspace, show_progress=False)
            run_keyframes(KeyframeConfig(), dataset_root, workspace)
            run_sites(SiteConfig(), dataset_root, workspace, dataset=dataset)
        source = Workspace(sites_from or workspace)
        for site_id in read_site_ids(source.sites_index()):
            views = site_views(dataset, read_site_manifest(source.site_manifest(site_id)))
            images = has_images(dataset_root, views)
            if not images and reference is None:
                raise SystemExit(
                    f"{site} has no images and no measured site gives matching costs: bench a site with images "
                    "first (earlier in --site, or kept in --output)"
                )
            logger.info("%s %s: %d images, matching %s", site, site_id, len(views), images or "estimated")
            out[site_id] = bench_views(
                dataset, site, views, workspace / site_id, sample, seed, None if images else reference
            )
    return out


def bench_views(
    dataset: Any,
    site: Path,
    views: list[CameraView],
    folder: Path,
    sample: int,
    seed: int,
    reference: dict[str, Any] | None,
) -> dict[str, Any]:
    """Pairs, recall and matching cost of each strategy on one site's keyframe images (matching timed on a
    sample, or estimated from `reference` when given: the site has no images)."""
    config = PairsConfig()
    started = time.perf_counter()
    chosen, funnel = select_pairs(views, config)
    selection_s = time.perf_counter() - started
    repeats = repeated_views(views, config)
    started = time.perf_counter()
    covisibility = covisibility_matrix(
        true_views(views, site), surface(site), grid=(15, 60), show_progress=True
    )
    strong = strong_sets(covisibility)
    del covisibility
    truth_s = time.perf_counter() - started
    n = len(views)
    exhaustive_count = n * (n - 1) // 2
    strategies: dict[str, set[Pair] | None] = {
        "exhaustive": None,
        "sequential": set(sequential_pairs(views, config)),
        "sequential+hsp": set(chosen),
    }
    rng = random.Random(seed)
    report: dict[str, Any] = {
        "images": n,
        "images_rendered": reference is None,
        "selection_seconds": selection_s,
        "truth_seconds": truth_s,
    }
    report["strong_pairs"] = {name: len(pairs) for name, pairs in strong.items()}
    report["hsp_funnel"] = funnel
    for name, pairs in strategies.items():
        count = exhaustive_count if pairs is None else len(pairs)
        recall = {
            k: 1.0 if pairs is None else recalled(s, pairs, repeats) / max(len(s), 1)
            for k, s in strong.items()
        }
        entry: dict[str, Any] = {
            "pairs": count,
            "share_of_exhaustive": count / exhaustive_count,
            "recall": recall,
        }
        if reference is None:
            (folder / name).mkdir(parents=True, exist_ok=True)
            picked = sample_pairs(pairs, n, sample, rng)
            entry["matching"] = time_matching(dataset, views, picked, folder / name, FeaturesConfig())
            cpu = {m: entry["matching"][m]["cpu_seconds_per_pair"] for m in MATCHERS}
            entry["estimated_matching_seconds"] = {
                m: entry["matching"][m]["seconds_per_pair"] * count for m in MATCHERS
            }
        else:
            entry["matching"] = estimated_matching(name, count, reference)
            cpu = entry["matching"]["reference_cpu_seconds_per_pair"]
        entry["estimated_matching_cpu_seconds"] = {m: cpu[m] * count for m in MATCHERS}
        report[name] = entry
        logger.info("%s: %d pairs, recall %s, matching %s", name, count, recall, entry["matching"])
    report["ratios"] = ratios(report, measured=reference is None)
    return report


def sample_pairs(pairs: set[Pair] | None, n: int, sample: int, rng: random.Random) -> list[Pair]:
    """Up to `sample` random pairs of a strategy (None: exhaustive, drawn without listing every pair)."""
    if pairs is not None:
        return sorted(rng.sample(sorted(pairs), min(sample, len(pairs))))
    drawn: set[Pair] = set()
    while len(drawn) < min(sample, n * (n - 1) // 2):
        i, j = sorted(rng.sample(range(n), 2))
        drawn.add((i, j))
    return sorted(drawn)


def ratios(report: dict[str, Any], *, measured: bool) -> dict[str, float]:
    """HSP over exhaustive (pairs, matching CPU, and matching wall time when measured) and blas over colmap
    (when measured)."""
    hsp, full = report["sequential+hsp"], report["exhaustive"]
    out = {
        "pairs_hsp_over_exhaustive": hsp["pairs"] / full["pairs"],
        "matching_cpu_hsp_over_exhaustive": hsp["estimated_matching_cpu_seconds"]["blas"]
        / full["estimated_matching_cpu_seconds"]["blas"],
    }
    if not measured:
        return out
    blas, colmap = hsp["matching"]["blas"], hsp["matching"]["colmap"]
    return out | {
        "matching_time_hsp_over_exhaustive": hsp["estimated_matching_seconds"]["blas"]
        / full["estimated_matching_seconds"]["blas"],
        "matching_cpu_blas_over_colmap": blas["cpu_seconds_per_pair"] / colmap["cpu_seconds_per_pair"],
        "matching_wall_blas_over_colmap": blas["seconds_per_pair"] / colmap["seconds_per_pair"],
    }


def previous_results(path: Path, config: dict[str, Any]) -> dict[str, Any]:
    """The output file's site entries and their commands, to merge into; none when absent or made with another
    config (its figures would not compare)."""
    empty: dict[str, Any] = {"sites": {}, "commands": {}}
    if not path.is_file():
        return empty
    previous = json.loads(path.read_text())
    if previous.get("config") != config:
        logger.warning("%s was made with another config: its entries are not kept", path)
        return empty
    commands = previous.get("commands") or {site: previous.get("command", "") for site in previous["sites"]}
    return {"sites": previous["sites"], "commands": commands}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--site", type=Path, action="append", help="Generated site folder (repeatable).")
    parser.add_argument(
        "--sample", type=int, default=150, help="Pairs matched per strategy to time matching."
    )
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--workspace", type=Path, help="Read the sites of this workspace (one site folder only)."
    )
    parser.add_argument("--output", type=Path, default=RESULTS / "pairs.json")
    args = parser.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    sites = args.site or [Path("data/synthetic/default")]
    if args.workspace is not None and len(sites) != 1:
        parser.error("--workspace goes with exactly one --site")
    command = " ".join([Path(sys.executable).name, *sys.argv])
    config = json.loads(
        json.dumps({"pairs": PairsConfig().__dict__, "sample": args.sample, "strong": STRONG})
    )
    results = previous_results(args.output, config)
    results |= {
        "command": command,
        "config": config,
        "machine": {"python": platform.python_version(), "platform": platform.platform()},
    }
    for site in sites:
        reference = measured_reference(results["sites"])
        results["sites"][str(site)] = bench_site(site, args.sample, args.seed, args.workspace, reference)
        results["commands"][str(site)] = command
    print(json.dumps(results, indent=2, default=str))
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(json.dumps(results, indent=2, default=str) + "\n")


if __name__ == "__main__":
    main()
