"""The pairs stage on clips whose heights WIGO left free: the height rule with and without the tie.

With 2D logged poses and no GNSS, WIGO's clip heights are its gauge's (`bench/logged_height.py`), and the pairs
stage's height rule (`PairsConfig.max_dz_m`, 3 m) compares them across clips. `cama_pipeline/site/heights.py` ties
each free-height clip to the road the other clips drove first (`PairsConfig.level_free_heights`, on by default).
For each site (its `workspace-logged-height`, after `cama run`): the pairs selected without and with the tie (all,
across clips, dropped by the height rule), the tie's offset per clip, and how far apart the clips' WIGO heights
stay after it (each clip's median height error against the truth, `bench/logged_height.py`'s offsets, plus its
tie: the spread of the sums).

Usage: .venv/bin/python bench/free_height_pairs.py --site SITE [--site SITE ...] [--out bench/results/free_height_pairs.json]
"""

import argparse
import logging
from pathlib import Path
from typing import Any

from logged_height import WORKSPACE, height_offsets  # bench/logged_height.py: this folder is on sys.path
from paired_runs import write_results  # bench/paired_runs.py

from cama_pipeline.cameras import CameraView, site_views
from cama_pipeline.data import load_dataset
from cama_pipeline.pairs.config import PairsConfig
from cama_pipeline.pairs.stage import free_height_offsets, select_pairs
from cama_pipeline.site.io import read_site_manifest
from cama_pipeline.workspace import Workspace

RESULTS = Path(__file__).parent / "results"


def pair_counts(views: list[CameraView], offsets: dict[str, float] | None) -> dict[str, Any]:
    """Pairs selected with the heights moved by `offsets`: all, across clips, and the HSP funnel's drops."""
    pairs, funnel = select_pairs(views, PairsConfig(), offsets)
    return {
        "pairs": len(pairs),
        "cross_clip": sum(1 for i, j in pairs if views[i].scene != views[j].scene),
        "dropped": funnel["dropped"],
    }


def site_figures(site: Path, site_id: str) -> dict[str, Any]:
    """The pairs without and with the tie, the offsets, and the clips' WIGO height spread before and after."""
    workspace = Workspace(site / WORKSPACE)
    dataset = load_dataset(site / "nuscenes", check_files=False)
    views = site_views(dataset, read_site_manifest(workspace.site_manifest(site_id)))
    offsets = free_height_offsets(workspace, views, PairsConfig())
    errors = {
        scene: clip["offset_cm"]
        for scene, clip in height_offsets(site, workspace, site_id)["wigo"]["clips"].items()
    }
    tied = {scene: error + 100 * offsets.get(scene, 0.0) for scene, error in errors.items()}
    return {
        "without_tie": pair_counts(views, None),
        "with_tie": pair_counts(views, offsets),
        "tie_offsets_m": offsets,
        "wigo_clip_height_errors_cm": errors,
        "wigo_spread_cm": round(max(errors.values()) - min(errors.values()), 2),
        "tied_spread_cm": round(max(tied.values()) - min(tied.values()), 2),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--site", type=Path, action="append", required=True)
    parser.add_argument("--site-id", default="site-001")
    parser.add_argument("--out", type=Path, default=RESULTS / "free_height_pairs.json")
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)
    sites = {str(site): site_figures(site, args.site_id) for site in args.site}
    summary = {
        site: {
            "cross_clip_pairs": [f["without_tie"]["cross_clip"], f["with_tie"]["cross_clip"]],
            "spread_cm": [f["wigo_spread_cm"], f["tied_spread_cm"]],
        }
        for site, f in sites.items()
    }
    write_results(args.out, {"sites": sites, "summary": summary}, "summary")


if __name__ == "__main__":
    main()
