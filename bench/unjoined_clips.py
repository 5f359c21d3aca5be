"""The whole path when no point joins a site's clips, on logged poses without heights.

With 2D logged poses (every ego_pose z = 0, as nuScenes logs them) and no GNSS, WIGO leaves each clip at its own
height (`bench/logged_height.py`: up to 2.7 m apart). SfM joins clips through the points their cross-clip matches
tie (the merge's alignment, then the merged BA over every match); clips with no cross-clip match (matching fails
across them, or the pairs stage's `max_dz_m` drops their pairs: WIGO's offsets can exceed its 3 m) keep WIGO's
heights unless the merge ties them to the road the other clips drove (`cama_pipeline/sfm/height_ties.py`). The
synthetic sites' clips all share points, so this bench takes them apart: three workspaces, each a copy of the
site's `workspace-logged-height` (made by `bench/logged_height.py`, or here by `cama run`), `cama run` in each with
  - joined: the defaults (the clips joined by their points: the reference);
  - unjoined, tied: no spatial pairs (`[pairs] knn_radius_m` 1 mm: sequential and rig pairs only, so no match
    crosses clips), heights tied (the default);
  - unjoined, untied: the same with `[sfm_merge] height_ties = false` (the merge before the tie).
Each run measured as `bench/logged_height.py` measures one (`bench/segment.py`'s figures, per-clip height offsets
of the WIGO and SfM poses, elevation RMSE about its offset), with the merge's groups and height ties.

Usage: .venv/bin/python bench/unjoined_clips.py --site SITE-no-logged-height [--out bench/results/unjoined_clips.json]
"""

import argparse
import json
import logging
import shutil
from pathlib import Path
from typing import Any

from logged_height import (
    WORKSPACE,
    run_figures_with_heights,
)  # bench/logged_height.py: this folder is on sys.path
from paired_runs import path_differences, write_results  # bench/paired_runs.py

from cama_pipeline.pairs.config import PairsConfig
from cama_pipeline.sfm.merge import MergeConfig
from cama_pipeline.synthetic.generate import MANIFEST
from cama_pipeline.workspace import Workspace
from cama_studio.config import PipelineConfig
from cama_studio.pipeline import run as run_pipeline

RESULTS = Path(__file__).parent / "results"
NO_SPATIAL_PAIRS = PairsConfig(knn_radius_m=1e-3)
"""Sequential and rig pairs only: no image is paired with another clip's."""
VARIANTS: dict[str, PipelineConfig] = {
    "joined": PipelineConfig(),
    "unjoined_tied": PipelineConfig(pairs=NO_SPATIAL_PAIRS),
    "unjoined_untied": PipelineConfig(pairs=NO_SPATIAL_PAIRS, sfm_merge=MergeConfig(height_ties=False)),
}


def measured_run(site: Path, name: str, config: PipelineConfig, site_id: str) -> dict[str, Any]:
    """`cama run` into `<site>/workspace-<name>` (a copy of `workspace-logged-height` when that exists) with the
    config; its figures and the merge's report."""
    workspace = Workspace(site / f"workspace-{name.replace('_', '-')}")
    source = site / WORKSPACE
    if not workspace.root.exists() and source.is_dir():
        shutil.copytree(source, workspace.root, symlinks=True)
    result = run_pipeline(
        site / "nuscenes",
        workspace.root,
        config,
        on_stage=lambda s: print(f"== {name} {s}", flush=True),
    )
    seconds = {k: round(v, 1) for k, v in result.seconds.items()}
    figures = run_figures_with_heights(site, seconds, site_id, workspace.root.name)
    merge_report = json.loads(workspace.sfm_report(site_id).read_text())["merge"]
    figures["merge"] = {key: merge_report.get(key) for key in ("groups", "alignments", "height_ties")}
    return figures


def differences(reference: dict[str, Any], other: dict[str, Any]) -> dict[str, float]:
    """`other` minus `reference`: the common figures, the SfM clips' height offsets' spread and the elevation
    RMSE about its offset."""
    out = path_differences(reference, other)
    out["sfm_clip_offset_spread_cm"] = round(
        other["clip_heights"]["sfm"]["offset_spread_cm"]
        - reference["clip_heights"]["sfm"]["offset_spread_cm"],
        2,
    )
    out["elevation_rmse_about_offset_cm"] = round(
        other["elevation_relative"]["rmse_about_offset_cm"]
        - reference["elevation_relative"]["rmse_about_offset_cm"],
        2,
    )
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--site", type=Path, required=True, help="a generated site without logged heights")
    parser.add_argument("--site-id", default="site-001")
    parser.add_argument("--out", type=Path, default=RESULTS / "unjoined_clips.json")
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)
    manifest = json.loads((args.site / MANIFEST).read_text())
    if manifest.get("logged_height", True):
        raise SystemExit(
            f"{args.site}: its logged poses carry heights; make it with `cama synth --no-logged-height`"
        )
    runs = {name: measured_run(args.site, name, config, args.site_id) for name, config in VARIANTS.items()}
    results = {
        "site": str(args.site),
        "runs": runs,
        "tied_minus_joined": differences(runs["joined"], runs["unjoined_tied"]),
        "untied_minus_joined": differences(runs["joined"], runs["unjoined_untied"]),
    }
    write_results(args.out, results, "tied_minus_joined")
    print(json.dumps(results["untied_minus_joined"], indent=1))


if __name__ == "__main__":
    main()
