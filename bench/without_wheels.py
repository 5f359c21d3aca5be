"""The whole path with one scene's wheel speeds missing, against the same site with them, in one run.

nuScenes' CAN bus expansion leaves some scenes out; WIGO then passes such a scene's logged ego poses through
unfused (`[wigo] without_wheels`, `cama_pipeline.wigo.logged_only`). This bench makes a copy of `--site` whose data
set lacks `--scene`'s wheel file (the other files hard-linked, the ground truth linked), runs `cama run` on the site
and on the copy, each into its own `workspace-wheels`, both with the generator's masks (the data set's, or those
in ground_truth/ for a mask-free site), and measures each run as `bench/segment.py` measures one (SfM pose error,
elevation RMSE, BEV IoU, proposal mAP, SRE at 960x540, the simulated annotator), plus the SfM pose error of the
scene itself; then the copy minus the site.

Usage: .venv/bin/python bench/without_wheels.py --site SITE [--scene scene-0001] [--copy DIR]
       [--out bench/results/without_wheels.json]
"""

import argparse
import logging
import os
import shutil
from pathlib import Path
from typing import Any

from end_to_end import pose_figures  # bench/end_to_end.py: this script's folder is on sys.path
from paired_runs import path_differences, write_results  # bench/paired_runs.py
from segment import run_figures  # bench/segment.py

from cama_pipeline.cameras import site_views
from cama_pipeline.data.masks import has_masks
from cama_pipeline.data.schema import CAN_DIR, WHEEL_MESSAGE, can_file_name
from cama_pipeline.site.io import read_site_manifest
from cama_pipeline.synthetic.generate import DATASET_DIR, GROUND_TRUTH_DIR, MANIFEST, truth_dataset
from cama_pipeline.wigo.io import read_wigo
from cama_pipeline.workspace import Workspace
from cama_studio.config import PipelineConfig
from cama_studio.pipeline import run as run_pipeline
from models.vma.checkpoint import ensure_unseen
from models.vma.element_masks.checkpoint import load_mask_checkpoint
from models.vma.shipped import SHIPPED_MASK_REGISTRY, resolve_checkpoint

RESULTS = Path(__file__).parent / "results"
WORKSPACE = "workspace-wheels"


def copy_without_wheels(site: Path, copy: Path, scene: str) -> None:
    """`copy`: the site's data set hard-linked file by file without `scene`'s wheel file, its ground truth and
    manifest linked (made again from scratch each time)."""
    shutil.rmtree(copy, ignore_errors=True)
    copy.mkdir(parents=True)
    shutil.copytree(site / DATASET_DIR, copy / DATASET_DIR, copy_function=os.link)
    wheels = copy / DATASET_DIR / CAN_DIR / can_file_name(scene, WHEEL_MESSAGE)
    if not wheels.is_file():
        raise SystemExit(f"{site}: scene {scene} has no wheel file to leave out ({wheels.name})")
    wheels.unlink()
    (copy / GROUND_TRUTH_DIR).symlink_to((site / GROUND_TRUTH_DIR).absolute())
    (copy / MANIFEST).symlink_to((site / MANIFEST).absolute())


def scene_pose_error(site: Path, workspace: Workspace, site_id: str, scene: str) -> dict[str, Any]:
    """`bench/end_to_end.py`'s WIGO and SfM pose figures of the scene's images alone."""
    views = site_views(truth_dataset(site), read_site_manifest(workspace.site_manifest(site_id)))
    return pose_figures(site, [v for v in views if v.scene == scene], workspace, site_id)


def measured_run(site: Path, masks: str, site_id: str, scene: str) -> dict[str, Any]:
    """`cama run` into `<site>/workspace-wheels` and its figures."""
    workspace = Workspace(site / WORKSPACE)
    result = run_pipeline(
        site / DATASET_DIR,
        workspace.root,
        PipelineConfig(masks=masks),
        on_stage=lambda s: print(f"== {site.name} {s}", flush=True),
    )
    seconds = {k: round(v, 1) for k, v in result.seconds.items()}
    figures = run_figures(site, workspace, site_id, seconds)
    figures["scene_poses"] = scene_pose_error(site, workspace, site_id, scene)
    figures["scene_wigo_report"] = read_wigo(workspace.wigo(scene)).report
    return figures


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--site", type=Path, required=True)
    parser.add_argument("--scene", default="scene-0001")
    parser.add_argument("--copy", type=Path, default=None, help="default: SITE-without-wheels beside it")
    parser.add_argument("--site-id", default="site-001")
    parser.add_argument("--out", type=Path, default=RESULTS / "without_wheels.json")
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)
    site = args.site
    copy = args.copy or site.with_name(site.name + "-without-wheels")
    ensure_unseen(load_mask_checkpoint(resolve_checkpoint(None, SHIPPED_MASK_REGISTRY)), site)
    masks = "dataset" if has_masks(site / DATASET_DIR) else str((site / GROUND_TRUTH_DIR).absolute())
    copy_without_wheels(site, copy, args.scene)
    runs = {
        "with_wheels": measured_run(site, masks, args.site_id, args.scene),
        "without_wheels": measured_run(copy, masks, args.site_id, args.scene),
    }
    a, b = runs["with_wheels"], runs["without_wheels"]
    differences = path_differences(a, b)
    differences["scene_sfm_position_cm"] = round(
        b["scene_poses"]["sfm"]["position_cm"] - a["scene_poses"]["sfm"]["position_cm"], 4
    )
    results = {"site": str(site), "scene": args.scene, "runs": runs, "without_minus_with": differences}
    write_results(args.out, results, "without_minus_with")


if __name__ == "__main__":
    main()
