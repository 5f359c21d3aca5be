"""The whole path on logged poses without heights, as real nuScenes logs them, against the same site with them.

nuScenes' localization is 2D: every ego_pose has z = 0. WIGO then leaves the height to the wheels and the IMU
(`[wigo] free_flat_logged_height`) and holds each clip's height gauge near z = 0 at its first pose, so clips that
start at different true heights come out of WIGO at different offsets; SfM and the surface must join them. This
bench runs `cama run` on two sites made from one config, in one run, each into its own `workspace-logged-height`:
    .venv/bin/cama synth --preset default --no-masks --out SITE
    .venv/bin/cama synth --preset default --no-masks --no-logged-height --out SITE-no-logged-height
(refused unless their manifests hold the same config and differ in `logged_height` only). Both data sets are
mask-free, so both runs segment their images with the shipped network (the same images: the same masks).
Each run is measured as `bench/segment.py` measures one (SfM pose error, elevation RMSE, BEV IoU, proposal mAP,
SRE at 960x540, the simulated annotator), and beyond it:
  - the elevation RMSE once the median offset over the scored cells is removed, and that offset: no measurement
    of a data set without logged heights or GNSS fixes the absolute height (the exports' ego frames and the
    surface read heights relative to the poses);
  - per clip, the median height offset of the WIGO and the SfM key-frame poses from the truth, and the RMSE about
    it: the spread of the clips' offsets is how far apart in height the clips were left.
Then the differences, no-logged-height minus logged-height.

`--measure-only` skips `cama run` and measures the two workspaces as the last run left them (no stage seconds).

Usage: .venv/bin/python bench/logged_height.py --site SITE [--planar-site SITE-no-logged-height] [--measure-only]
       [--out bench/results/logged_height.json]
"""

import argparse
import json
import logging
from pathlib import Path
from typing import Any

import numpy as np
from end_to_end import elevation_figures  # bench/end_to_end.py: this script's folder is on sys.path
from paired_runs import path_differences, write_results  # bench/paired_runs.py
from segment import pipeline_run, run_figures  # bench/segment.py

from cama_pipeline.cameras import site_views
from cama_pipeline.evaluate import load_true_poses
from cama_pipeline.segment.checkpoint import ensure_unseen as ensure_segmenter_unseen
from cama_pipeline.segment.checkpoint import load_checkpoint as load_segmenter
from cama_pipeline.sfm.io import read_refined_poses
from cama_pipeline.site.io import read_site_manifest
from cama_pipeline.synthetic.generate import MANIFEST, truth_dataset
from cama_pipeline.wigo.io import read_wigo
from cama_pipeline.workspace import Workspace
from models.vma.checkpoint import ensure_unseen
from models.vma.element_masks.checkpoint import load_mask_checkpoint
from models.vma.shipped import SHIPPED_MASK_REGISTRY, resolve_checkpoint

RESULTS = Path(__file__).parent / "results"
WORKSPACE = "workspace-logged-height"
PLANAR_SUFFIX = "-no-logged-height"


def check_twins(site: Path, planar: Path) -> None:
    """Refuse (SystemExit naming both) unless the two sites hold one config, with and without logged heights."""
    manifests = [json.loads((s / MANIFEST).read_text()) for s in (site, planar)]
    if manifests[0]["config"] != manifests[1]["config"]:
        raise SystemExit(f"{site} and {planar} were not generated from the same config")
    heights = [m.get("logged_height", True) for m in manifests]
    if heights != [True, False]:
        raise SystemExit(
            f"{site} must have logged heights and {planar} none (`cama synth --no-logged-height`); "
            f"their manifests say logged_height {heights[0]} and {heights[1]}"
        )
    if any(m.get("masks_in_dataset", True) != manifests[0].get("masks_in_dataset", True) for m in manifests):
        raise SystemExit(f"{site} and {planar} differ in their masks (both --no-masks, or neither)")


def height_offsets(site: Path, workspace: Workspace, site_id: str) -> dict[str, Any]:
    """Per clip: the median height offset of the WIGO and SfM key-frame ego poses from the truth, and the RMSE
    about it (cm); and the spread (max - min) of the clips' offsets."""
    truth = load_true_poses(site / "ground_truth" / "poses.json")
    views = site_views(truth_dataset(site), read_site_manifest(workspace.site_manifest(site_id)))
    refined = read_refined_poses(workspace.sfm_poses(site_id))
    sources = {
        "wigo": {v.token: (v.scene, v.world_from_ego[2, 3]) for v in views},
        "sfm": {v.token: (v.scene, refined[v.token][2, 3]) for v in views if v.token in refined},
    }
    out: dict[str, Any] = {}
    for source, heights in sources.items():
        errors: dict[str, list[float]] = {}
        for token, (scene, z) in heights.items():
            errors.setdefault(scene, []).append(z - truth[token].translation[2])
        clips = {}
        for scene, values in sorted(errors.items()):
            error = np.array(values)
            offset = float(np.median(error))
            clips[scene] = {
                "offset_cm": round(offset * 100, 2),
                "rmse_about_offset_cm": round(float(np.sqrt(np.mean((error - offset) ** 2))) * 100, 2),
            }
        offsets = [clip["offset_cm"] for clip in clips.values()]
        out[source] = {"clips": clips, "offset_spread_cm": round(max(offsets) - min(offsets), 2)}
    return out


def relative_elevation(site: Path, workspace: Workspace, site_id: str) -> dict[str, float | None]:
    """Elevation RMSE over the scored road cells once their median offset is removed, and that offset (cm)."""
    _, error = elevation_figures(site, workspace.surface_bev(site_id))
    values = error[np.isfinite(error)]
    if not values.size:
        return {"offset_cm": None, "rmse_about_offset_cm": None}
    offset = float(np.median(values))
    return {
        "offset_cm": round(offset * 100, 2),
        "rmse_about_offset_cm": round(float(np.sqrt(np.mean((values - offset) ** 2))) * 100, 2),
    }


def wigo_height_modes(workspace: Workspace) -> dict[str, str]:
    """What WIGO did with each clip's logged heights (its report's `logged_pose_height`)."""
    return {
        scene: read_wigo(workspace.wigo(scene)).report.get("logged_pose_height", "")
        for scene in workspace.wigo_scenes()
    }


def run_figures_with_heights(
    site: Path, seconds: dict[str, float], site_id: str, workspace_name: str = WORKSPACE
) -> dict[str, Any]:
    """`bench/segment.py`'s figures of the run in `<site>/<workspace_name>`, and the height figures."""
    workspace = Workspace(site / workspace_name)
    figures = run_figures(site, workspace, site_id, seconds)
    figures["wigo_logged_pose_height"] = wigo_height_modes(workspace)
    figures["elevation_relative"] = relative_elevation(site, workspace, site_id)
    figures["clip_heights"] = height_offsets(site, workspace, site_id)
    return figures


def differences(logged: dict[str, Any], planar: dict[str, Any]) -> dict[str, float]:
    """No-logged-height minus logged-height: the common figures, and the relative elevation and the SfM clips'
    height offsets' spread."""
    out = path_differences(logged, planar)
    for key, pick in (
        ("elevation_rmse_about_offset_cm", lambda run: run["elevation_relative"]["rmse_about_offset_cm"]),
        ("sfm_clip_offset_spread_cm", lambda run: run["clip_heights"]["sfm"]["offset_spread_cm"]),
    ):
        out[key] = round(float(pick(planar)) - float(pick(logged)), 4)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--site", type=Path, required=True, help="a generated site with logged heights")
    parser.add_argument("--planar-site", type=Path, default=None, help="default: SITE-no-logged-height")
    parser.add_argument("--site-id", default="site-001")
    parser.add_argument("--out", type=Path, default=RESULTS / "logged_height.json")
    parser.add_argument(
        "--measure-only", action="store_true", help="the workspaces as they are, no `cama run`"
    )
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)
    site = args.site
    planar = args.planar_site or site.with_name(site.name + PLANAR_SUFFIX)
    check_twins(site, planar)
    for each in (site, planar):  # SeenSiteError when a shipped network trained on the site
        ensure_unseen(load_mask_checkpoint(resolve_checkpoint(None, SHIPPED_MASK_REGISTRY)), each)
        ensure_segmenter_unseen(load_segmenter(None), each)
    runs = {}
    for name, each in (("logged_height", site), ("no_logged_height", planar)):
        seconds = {} if args.measure_only else pipeline_run(each, "auto", WORKSPACE)[1]
        runs[name] = run_figures_with_heights(each, seconds, args.site_id)
    results = {
        "measure_only": args.measure_only,
        "sites": {"logged_height": str(site), "no_logged_height": str(planar)},
        "runs": runs,
        "no_logged_minus_logged": differences(runs["logged_height"], runs["no_logged_height"]),
    }
    write_results(args.out, results, "no_logged_minus_logged")


if __name__ == "__main__":
    main()
