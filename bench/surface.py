"""Road surface benchmark: the reconstructed BEV rasters of a synthetic site against its ground truth.

For each pose source (ground_truth, wigo, and sfm when the workspace has `sfm/<site>/poses.json`),
`cama surface` runs into its own temporary workspace (sharing the site's `sites/` and `sfm/`), and its rasters
are compared with the site's truth at each reconstructed cell's centre (the generator's world rebuilt from the
site's manifest and rendered on the reconstruction's own grid, `cama_pipeline.synthetic.truth_grid`; unobserved where
the stored `ground_truth/bev/` is):
  elevation  RMSE / MAE / p95 of |z - z_true| over observed road cells (true class road, marking, crosswalk),
             the median signed error (an offset of the pose frame shows there), and RMSE by distance from
             the site's keyframe trajectory (beyond the strip it is extrapolated);
  semantic   IoU per class (road, curb, lane marking, crosswalk) over cells observed in both rasters, and where
             the curb IoU is lost (`curb_confusion`: true curb cells labelled road or background, curb labels on
             true road or background);
  photometric PSNR of the BEV colour against the true top-down albedo over cells observed in both, raw and
             after a per-channel gain/offset fit (the images are shaded, the truth is albedo);
  own frame  the semantic and photometric figures again against the truth carried into the reconstruction's frame
             (`in_reconstruction_frame`: the best 2D similarity of its key frames onto the true ones,
             `cama_pipeline.evaluate.frame`): what the stage makes of its poses, their absolute error aside;
  ego frames the heights (road; road and kerbs) and class IoU again in each key frame's ego frame within MapTR's
             range (`in_ego_frames`, `cama_pipeline.evaluate.ego_frames`), each source's surface under its own
             poses against the truth under the true ones: what the exports' consumer reads, where a height
             offset, tilt or shift that the poses and the surface share cancels;
  coverage   observed cells, and the share of the truly observed road cells that are reconstructed;
  kerbs      the surface standing on its kerb steps (elevation + `kerb_step.npy`) against the truth, whose
             sidewalks are raised: RMSE over the true curb cells and over road and curb cells together, and the
             raised cells' precision / recall against the observed off-road cells truly > 6.5 cm above the
             road-level elevation;
  runtime    seconds per phase from the stage's report.
Baseline in the same run, ground-truth poses: the surface without the curvature prior, the SfM gate and the
curb-height vote (`smoothness_weight 0, sfm_gate_m 1e6, curb_height_m 0`); and the last pose source again
without the kerb step (`kerb_step.enabled false`), its ablation, and with the kerb's foot raised and relabelled
(`kerb_step.kerb_band_m`, `--kerb-band`, off by default: one width along each kerb), and with the kerb line of the
two class votes toggled (`kerb_step.kerb_line`, `variant_kerb_line_toggled`); and the first and the last pose
source without the multi-view refinement of the road elevation (`refine.enabled false`): the observation vote on
the fitted elevation alone, as the stage was before the refinement. Adam on the per-vertex colours and logits (`colour_lr`, `semantic_lr` > 0) was measured before and costs 1.7 dB PSNR; not rerun here.

Usage: .venv/bin/python bench/surface.py [--site data/synthetic/default] [--resolution 0.1] [--epochs 1]
       [--sources ground_truth,sfm] [--out bench/results/surface.json]
Prints the figures and writes them to `--out` (bench/results/surface.json by default).
"""

import argparse
import logging
import platform
import shutil
import sys
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import torch
from scipy import ndimage

from cama_pipeline.bev import BevRasters, read_bev
from cama_pipeline.cameras import CameraView
from cama_pipeline.data import load_dataset
from cama_pipeline.data.masks import has_masks
from cama_pipeline.evaluate.ego_frames import ego_class_iou, ego_height_errors
from cama_pipeline.evaluate.frame import reconstruction_frame
from cama_pipeline.evaluate.photometric import affine_fit, psnr
from cama_pipeline.io import atomic_write_json
from cama_pipeline.semantics import ROAD_SURFACE_IDS, Semantic
from cama_pipeline.site.io import read_site_ids, read_site_manifest
from cama_pipeline.surface import SurfaceConfig, run
from cama_pipeline.surface import stage as surface_stage
from cama_pipeline.surface.coverage import CoverageConfig, support_distance
from cama_pipeline.surface.outputs import read_kerb_step
from cama_pipeline.surface.points import ego_poses
from cama_pipeline.surface.poses import posed_views
from cama_pipeline.synthetic.truth_grid import (
    TrueGround,
    cell_centres,
    nearest_true_cells,
    truth_on_grid,
)
from cama_pipeline.workspace import StageFolder, Workspace

RESULTS = Path(__file__).parent / "results"
BANDS_M = ((0, 2), (2, 4), (4, 6), (6, 8), (8, 10), (10, 14), (14, 100))
NEAR_TRAJECTORY_M = 4.0
"""Road cells this near a keyframe position give the surface's height offset (that of its pose frame)."""
IOU_CLASSES = {"road": Semantic.ROAD, "curb": Semantic.CURB, "lane_marking": Semantic.LANE_MARKING}
IOU_CLASSES["crosswalk"] = Semantic.CROSSWALK
EGO_STRIDE = 5
"""The ego-frame heights are scored on every 5th cell along rows and columns (0.5 m apart at 0.1 m cells)."""
logger = logging.getLogger("bench.surface")


def truth_at(ours: BevRasters, truth: BevRasters) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(rows, cols) of our cells and the nearest true cells (-1 when outside the true raster)."""
    shape = ours.georeference.shape
    inside, true_rows, true_cols = nearest_true_cells(cell_centres(ours.georeference), truth)
    return inside.reshape(shape), true_rows.reshape(shape), true_cols.reshape(shape)


def distance_from_trajectory(ours: BevRasters, trajectory_xy: np.ndarray) -> np.ndarray:
    """(rows, cols) distance (m) of every cell from the nearest keyframe position."""
    geo = ours.georeference
    colrow = np.round(geo.pixel_from_global(trajectory_xy)).astype(int)
    free = np.ones(geo.shape, bool)
    free[colrow[:, 1], colrow[:, 0]] = False
    return ndimage.distance_transform_edt(free, sampling=geo.resolution)


def rmse_by_distance(road: np.ndarray, error: np.ndarray, distance: np.ndarray) -> dict[str, float | None]:
    """Elevation RMSE of the road cells in bands of `distance` (m) from the nearest keyframe position."""
    bands = {}
    for lo, hi in BANDS_M:
        band = road & (distance >= lo) & (distance < hi)
        bands[f"{lo}-{hi}"] = float(np.sqrt(np.mean(error[band] ** 2))) if band.any() else None
    return bands


def rmse(values: np.ndarray) -> float | None:
    return float(np.sqrt(np.mean(values**2))) if len(values) else None


def kerb_figures(
    signed_road_level: np.ndarray, kerb_step: np.ndarray, observed: np.ndarray, true_sem: np.ndarray
) -> dict[str, Any]:
    """The surface with its kerb steps against the truth (raised sidewalks included): elevation RMSE over the
    true curb cells and over the road and curb cells together, and how the raised cells agree with the cells
    that truly stand more than half the step above the road-level elevation (observed off-road cells)."""
    step = np.nan_to_num(kerb_step)
    signed = signed_road_level + step
    curb = observed & (true_sem == int(Semantic.CURB))
    road_or_curb = observed & (np.isin(true_sem, ROAD_SURFACE_IDS) | (true_sem == int(Semantic.CURB)))
    off_road = observed & ~np.isin(true_sem, ROAD_SURFACE_IDS) & (true_sem != 255)
    height = float(step.max()) if (step > 0).any() else 0.0
    truly_raised = -signed_road_level > 0.065  # half of the generator's 0.10-0.15 m curbs
    raised = step > 0
    hits = (raised & truly_raised & off_road).sum()
    return {
        "step_height_m": height,
        "elevation_rmse_m_curb_cells": rmse(signed[curb]),
        "elevation_rmse_m_curb_cells_road_level": rmse(signed_road_level[curb]),
        "elevation_rmse_m_road_and_curb": rmse(signed[road_or_curb]),
        "raised_precision": float(hits / max((raised & off_road).sum(), 1)),
        "raised_recall": float(hits / max((truly_raised & off_road).sum(), 1)),
    }


def curb_confusion(semantic: np.ndarray, true_sem: np.ndarray, both: np.ndarray) -> dict[str, float]:
    """Where the curb IoU is lost: the shares of the true curb cells labelled a road class or background, and
    of the cells labelled curb that are truly road (a curb label bleeding onto the road) or background."""
    road_ids = list(ROAD_SURFACE_IDS)
    true_curb = both & (true_sem == int(Semantic.CURB))
    ours_curb = both & (semantic == int(Semantic.CURB))

    def share(where: np.ndarray, of: np.ndarray) -> float:
        return float(where.sum() / max(of.sum(), 1))

    return {
        "true_curb_labelled_road": share(true_curb & np.isin(semantic, road_ids), true_curb),
        "true_curb_labelled_background": share(true_curb & (semantic == int(Semantic.BACKGROUND)), true_curb),
        "curb_label_on_true_road": share(ours_curb & np.isin(true_sem, road_ids), ours_curb),
        "curb_label_on_true_background": share(ours_curb & (true_sem == int(Semantic.BACKGROUND)), ours_curb),
    }


def class_figures(ours: BevRasters, truth: BevRasters) -> dict[str, Any]:
    """IoU per class, where the curb IoU is lost, and the photometric PSNR (raw and after a per-channel gain and
    offset) of `ours` against `truth`, over the cells observed in both."""
    inside, tr, tc = truth_at(ours, truth)
    semantic = ours.require("semantic")
    true_sem = np.where(inside, truth.require("semantic")[tr, tc], 255)
    both = inside & (semantic != 255) & (true_sem != 255)
    ious = {}
    for name, cls in IOU_CLASSES.items():
        a, b = semantic[both] == int(cls), true_sem[both] == int(cls)
        ious[name] = float((a & b).sum() / max((a | b).sum(), 1))
    rgb, true_rgb = ours.require("photometric")[both], truth.require("photometric")[tr[both], tc[both]]
    return {
        "iou": ious,
        "curb_confusion": curb_confusion(semantic, true_sem, both),
        "psnr_db": psnr(rgb, true_rgb),
        "psnr_affine_db": psnr(affine_fit(rgb, true_rgb), true_rgb),
    }


def compare(
    ours: BevRasters, truth: BevRasters, trajectory_xy: np.ndarray, kerb_step: np.ndarray
) -> dict[str, Any]:
    """Elevation (road level, and with the kerb steps), semantic, photometric and coverage figures of `ours`
    against `truth`."""
    inside, tr, tc = truth_at(ours, truth)
    semantic, true_semantic = ours.require("semantic"), truth.require("semantic")
    true_sem = np.where(inside, true_semantic[tr, tc], 255)
    observed = inside & (semantic != 255)
    road = observed & np.isin(true_sem, ROAD_SURFACE_IDS)
    signed = ours.require("elevation") - truth.require("elevation")[tr, tc]
    error = np.abs(signed[road])
    distance = distance_from_trajectory(ours, trajectory_xy)
    near = road & (distance < NEAR_TRAJECTORY_M)
    true_road = np.isin(true_semantic, ROAD_SURFACE_IDS).sum()
    scale = (ours.georeference.resolution / truth.georeference.resolution) ** 2
    return {
        "elevation_rmse_m": float(np.sqrt(np.mean(error**2))),
        "elevation_mae_m": float(np.mean(error)),
        "elevation_p95_m": float(np.percentile(error, 95)),
        "elevation_median_signed_m": float(np.median(signed[road])),
        "elevation_median_signed_m_near_trajectory": float(np.median(signed[near])) if near.any() else None,
        "road_cells_evaluated": int(road.sum()),
        "elevation_rmse_m_by_distance_from_trajectory_m": rmse_by_distance(road, signed, distance),
        **class_figures(ours, truth),
        "cells_observed": int(observed.sum()),
        "true_road_coverage": float(road.sum() * scale / max(true_road, 1)),
        "kerb": kerb_figures(signed, kerb_step, observed, true_sem),
    }


def first_image_per_keyframe(views: list[CameraView]) -> list[CameraView]:
    """One image per key frame (scene, frame index): the first camera's in channel order."""
    first: dict[tuple[str, int], CameraView] = {}
    for view in sorted(views, key=lambda v: (v.scene, v.frame_index, v.channel)):
        first.setdefault((view.scene, view.frame_index), view)
    return list(first.values())


def ego_frame_figures(
    ground: TrueGround,
    ours: BevRasters,
    kerb_step: np.ndarray,
    our_views: list[CameraView],
    true_views: list[CameraView],
) -> dict[str, object]:
    """The surface in each key frame's ego frame, within MapTR's range: what a consumer of the exports sees
    (`cama_pipeline.evaluate.ego_frames`). Heights on every EGO_STRIDE-th row and column: the road (cells labelled
    a road class, against the true road) and the road with the kerbs (cells labelled curb too, standing on their
    kerb step, against the true road and curb, raised as they are). Classes on every observed cell. Each key frame
    at an image both sources posed (the ego pose moves between the cameras' firing times), keyed by its token."""
    true_by_token = {v.token: v.world_from_ego for v in true_views}
    keyframes = first_image_per_keyframe([v for v in our_views if v.token in true_by_token])
    ours_poses = {v.token: v.world_from_ego for v in keyframes}
    true_poses = {v.token: true_by_token[v.token] for v in keyframes}
    semantic = ours.require("semantic")
    centres = cell_centres(ours.georeference)
    sampled = np.zeros(semantic.shape, dtype=bool)
    sampled[::EGO_STRIDE, ::EGO_STRIDE] = True
    height = ours.require("elevation") + np.nan_to_num(kerb_step)
    curb = (int(Semantic.CURB),)
    figures: dict[str, object] = {"stride_cells": EGO_STRIDE}
    for name, classes in (("road", ROAD_SURFACE_IDS), ("road_and_curb", (*ROAD_SURFACE_IDS, *curb))):
        cells = sampled & np.isin(semantic, classes)
        points = np.column_stack([centres[cells.ravel()], height[cells]])
        errors = ego_height_errors(points, ours_poses, true_poses, ground.height_of(classes))
        figures[f"heights_{name}"] = errors.summary()
    observed = semantic != int(Semantic.UNOBSERVED)
    points = np.column_stack([centres[observed.ravel()], ours.require("elevation")[observed]])
    iou_classes = {name: int(cls) for name, cls in IOU_CLASSES.items()}
    figures["iou"] = ego_class_iou(
        points, semantic[observed], ours_poses, true_poses, ground.label, iou_classes
    )
    return figures


@contextmanager
def captured_support() -> Iterator[dict[str, np.ndarray]]:
    """While open, the points the stage fitted its elevation to, as it hands them to the report's
    `extrapolated_heights`, are kept in the yielded dict under "xy" (the stage's function wrapped; nothing it
    computes changes)."""
    kept: dict[str, np.ndarray] = {}
    original = surface_stage.extrapolated_heights

    def capture(support_xy: np.ndarray, *args: Any, **kwargs: Any) -> dict[str, Any]:
        kept["xy"] = np.asarray(support_xy)
        return original(support_xy, *args, **kwargs)

    surface_stage.extrapolated_heights = capture  # type: ignore[assignment]
    try:
        yield kept
    finally:
        surface_stage.extrapolated_heights = original  # type: ignore[assignment]


def height_error_by_support(
    ours: BevRasters, truth: BevRasters, support_xy: np.ndarray, coverage: CoverageConfig, offset_m: float
) -> dict[str, Any]:
    """The road's elevation error (less the surface's `offset_m`, its pose frame's height) over the cells whose
    heights the report calls extrapolated (`cama_pipeline.surface.coverage`) and over the rest: is the report's
    flag where the heights are off? Cells labelled and truly road."""
    inside, tr, tc = truth_at(ours, truth)
    semantic = ours.require("semantic")
    true_semantic = np.where(inside, truth.require("semantic")[tr, tc], 255)
    labelled_road = (ours.require("observation_count") > 0) & np.isin(semantic, ROAD_SURFACE_IDS)
    road = labelled_road & np.isin(true_semantic, ROAD_SURFACE_IDS)
    error = ours.require("elevation") - truth.require("elevation")[tr, tc] - offset_m
    distance = support_distance(support_xy, labelled_road, ours.georeference, coverage.support_points)
    extrapolated = road & (distance > coverage.height_support_m)
    return {
        "offset_m": offset_m,
        "extrapolated": {"cells": int(extrapolated.sum()), "rmse_m": rmse(error[extrapolated])},
        "supported": {
            "cells": int((road & ~extrapolated).sum()),
            "rmse_m": rmse(error[road & ~extrapolated]),
        },
    }


def mask_choice(site: Path, masks: str) -> str:
    """The stage's `--masks` for a bench's `masks`: `generator` is the generator's masks that a mask-free site keeps
    in its `ground_truth/` (SystemExit naming the folder when it has none); any other value is the stage's own."""
    if masks != "generator":
        return masks
    folder = site / "ground_truth"
    if not has_masks(folder):
        raise SystemExit(
            f"{folder}: no generator masks (semantic/, lane_instance/); a site made with --no-masks has them"
        )
    return str(folder)


def run_source(
    site: Path, poses: str, config: SurfaceConfig, scratch: Path, masks: str = "auto"
) -> dict[str, Any]:
    """Run the stage with `poses` in a fresh workspace beside the real one, observing through `masks` (a choice of
    `cama surface --masks`, or `generator`: a mask-free site's generator masks in its `ground_truth/`); figures
    and seconds."""
    workspace = Workspace(scratch / f"{len(list(scratch.iterdir()))}-{poses}")
    workspace.root.mkdir(parents=True)
    source = Workspace.for_dataset(site / "nuscenes")
    shared_stages: tuple[StageFolder, ...] = ("sites", "sfm", "masks")  # masks: a mask-free site's predicted
    for shared in shared_stages:
        if source.stage_dir(shared).exists():
            workspace.stage_dir(shared).symlink_to(source.stage_dir(shared).absolute())
    started = time.perf_counter()
    with captured_support() as support:
        result = run(
            config,
            site / "nuscenes",
            workspace,
            poses=poses,
            masks=mask_choice(site, masks),
            overwrite=True,
            show_progress=False,
        ).items[0]
    seconds = time.perf_counter() - started
    manifest = read_site_manifest(workspace.site_manifest(result.name))
    dataset = load_dataset(site / "nuscenes")
    views = posed_views(dataset, manifest, workspace, result.name, "ground_truth")
    trajectory_xy = ego_poses(views)[:, :2, 3]
    our_views = posed_views(dataset, manifest, workspace, result.name, poses)
    ours = read_bev(workspace.surface_bev(result.name))
    kerb_step = read_kerb_step(workspace.surface_kerb_step(result.name), ours.georeference.shape)
    truth = truth_on_grid(site, ours.georeference)
    figures = compare(ours, truth, trajectory_xy, kerb_step)
    offset = figures["elevation_median_signed_m_near_trajectory"] or 0.0
    figures["height_error_by_support"] = height_error_by_support(
        ours, truth, support["xy"], config.coverage, offset
    )
    # the classes and colours again with the truth carried into the reconstruction's frame (the best 2D similarity
    # of its key frames onto the true ones): what the stage makes of its own poses, their absolute error aside
    frame = reconstruction_frame(site / "nuscenes", workspace, result.name)
    framed = truth_on_grid(site, ours.georeference, frame.world_of)
    figures["in_reconstruction_frame"] = {"frame": frame.as_dict(), **class_figures(ours, framed)}
    figures["in_ego_frames"] = ego_frame_figures(TrueGround.of(site), ours, kerb_step, our_views, views)
    report = result.report
    return {
        "poses": poses,
        "workspace": str(workspace.root),
        "site_id": result.name,
        "masks": masks if masks != "auto" else "dataset" if has_masks(site / "nuscenes") else "predicted",
        "refine": config.refine.enabled,
        "kerb_step": config.kerb_step.enabled,
        "kerb_band_m": config.kerb_step.kerb_band_m,
        "kerb_line": config.kerb_step.kerb_line,
        "epochs": config.epochs,
        "refine_elevation": config.refine_elevation,
        "colour_lr": config.colour_lr,
        "semantic_lr": config.semantic_lr,
        **figures,
        "seconds": {**report["seconds"], "total": seconds},
        "images": report["images"],
        "vertices": report["vertices"],
        "points": report["points"],
        "extrapolated_heights": report["extrapolated_heights"],
        "losses_last_epoch": report["losses"]["epochs"][-1:] or None,
        "refine_sweeps": report["losses"]["refine"],
    }


def _variant(row: dict[str, Any]) -> str:
    if not row["refine"]:
        return " vote"
    if not row["kerb_step"]:
        return " flat"
    return (" foot" if row["kerb_band_m"] > 0 else "") + (" line" if row["kerb_line"] else "")


def print_side_by_side(runs: list[dict[str, Any]]) -> None:
    """One column per pose source: elevation RMSE, IoU per class, PSNR, seconds per phase."""
    print(f"{'':>22}" + "".join(f"{row['poses'] + _variant(row):>14}" for row in runs))
    lines = {"elevation RMSE cm": [row["elevation_rmse_m"] * 100 for row in runs]}
    lines["RMSE road+curb cm"] = [(row["kerb"]["elevation_rmse_m_road_and_curb"] or 0) * 100 for row in runs]
    lines["RMSE curb cells cm"] = [(row["kerb"]["elevation_rmse_m_curb_cells"] or 0) * 100 for row in runs]
    lines["raised precision"] = [row["kerb"]["raised_precision"] for row in runs]
    lines["raised recall"] = [row["kerb"]["raised_recall"] for row in runs]
    for name in IOU_CLASSES:
        lines[f"IoU {name}"] = [row["iou"][name] for row in runs]
    for name in ("true_curb_labelled_road", "curb_label_on_true_road"):
        lines[name.replace("_", " ")[:22]] = [row["curb_confusion"][name] for row in runs]
    lines["PSNR dB"] = [row["psnr_db"] for row in runs]
    framed = [row["in_reconstruction_frame"] for row in runs]
    for name in IOU_CLASSES:
        lines[f"own frame IoU {name}"[:22]] = [f["iou"][name] for f in framed]
    lines["own frame PSNR dB"] = [f["psnr_db"] for f in framed]
    for phase in ("elevation", "refine", "observe", "optimise", "export", "total"):
        lines[f"seconds {phase}"] = [row["seconds"].get(phase, float("nan")) for row in runs]
    for label, values in lines.items():
        print(f"{label:>22}" + "".join(f"{v:>14.3f}" for v in values))


def refine_vs_vote(refined: dict[str, Any], vote: dict[str, Any]) -> dict[str, Any]:
    """The refined run against the vote alone with the same poses: elevation RMSE ratio, IoU and PSNR
    differences, time ratio."""
    return {
        "poses": refined["poses"],
        "elevation_rmse": refined["elevation_rmse_m"] / max(vote["elevation_rmse_m"], 1e-9),
        "iou_gain": {k: v - vote["iou"][k] for k, v in refined["iou"].items()},
        "psnr_db_gain": refined["psnr_db"] - vote["psnr_db"],
        "seconds": refined["seconds"]["total"] / max(vote["seconds"]["total"], 1e-9),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--site", type=Path, default=Path("data/synthetic/default"))
    parser.add_argument("--resolution", type=float, default=0.1)
    parser.add_argument("--epochs", type=int, default=SurfaceConfig.epochs)
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument(
        "--kerb-band", type=float, default=0.3, help="kerb_step.kerb_band_m of the kerb-foot variant run"
    )
    parser.add_argument(
        "--sources", default="ground_truth,wigo,sfm", help="pose sources (sfm only when the site has it)"
    )
    parser.add_argument("--out", type=Path, default=RESULTS / "surface.json", help="figures JSON")
    args = parser.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    config = SurfaceConfig(resolution_m=args.resolution, epochs=args.epochs, torch_threads=args.threads)
    source = Workspace.for_dataset(args.site / "nuscenes")
    finished_sfm = source.sites_index().is_file() and any(
        source.sfm_poses(site_id).is_file() for site_id in read_site_ids(source.sites_index())
    )
    sources = [s for s in args.sources.split(",") if s != "sfm" or finished_sfm]
    scratch = Path(tempfile.mkdtemp(prefix="bench-surface-"))
    try:
        without = replace(config, smoothness_weight=0.0, sfm_gate_m=1e6, curb_height_m=0.0)
        baseline = run_source(args.site, "ground_truth", without, scratch)
        runs = [run_source(args.site, source, config, scratch) for source in sources]
        flat = replace(config, kerb_step=replace(config.kerb_step, enabled=False))
        no_step = run_source(args.site, sources[-1], flat, scratch)
        foot = replace(config, kerb_step=replace(config.kerb_step, kerb_band_m=args.kerb_band))
        with_foot = run_source(args.site, sources[-1], foot, scratch)
        line = replace(config, kerb_step=replace(config.kerb_step, kerb_line=not config.kerb_step.kerb_line))
        with_line = run_source(args.site, sources[-1], line, scratch)
        vote = replace(config, refine=replace(config.refine, enabled=False))
        vote_sources = list(dict.fromkeys([sources[0], sources[-1]]))
        votes = [run_source(args.site, source, vote, scratch) for source in vote_sources]
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    for row in [baseline, *runs, no_step, with_foot, with_line, *votes]:
        print(
            f"{row['poses']:>12} epochs {row['epochs']}: elevation RMSE {row['elevation_rmse_m'] * 100:.2f} cm "
            f"(p95 {row['elevation_p95_m'] * 100:.1f} cm), IoU "
            + ", ".join(f"{k} {v:.3f}" for k, v in row["iou"].items())
            + f", PSNR {row['psnr_db']:.2f} dB (affine {row['psnr_affine_db']:.2f}), "
            f"{row['seconds']['total']:.0f} s {row['seconds']}"
        )
        print(
            "    RMSE by distance from the trajectory (m):",
            row["elevation_rmse_m_by_distance_from_trajectory_m"],
        )
    print_side_by_side([*runs, no_step, with_foot, with_line, *votes])
    reference = runs[0]
    stepped = runs[-1]
    results = {
        "command": " ".join([sys.executable.split("/")[-1], *sys.argv]),
        "site": str(args.site),
        "config": {"resolution_m": args.resolution, "epochs": args.epochs, "threads": args.threads},
        "machine": {
            "platform": platform.platform(),
            "torch": torch.__version__,
            "cuda": torch.cuda.is_available(),
        },
        "baseline_no_prior_no_gate_no_curb_height_gt_poses": baseline,
        "runs": runs,
        "ablation_no_kerb_step": no_step,
        "variant_kerb_foot": with_foot,
        "variant_kerb_line_toggled": with_line,
        "vote_runs": votes,
        "refine_vs_vote": [
            refine_vs_vote(next(r for r in runs if r["poses"] == v["poses"]), v) for v in votes
        ],
        "ratios_vs_baseline": {
            "elevation_rmse": reference["elevation_rmse_m"] / max(baseline["elevation_rmse_m"], 1e-9),
            "psnr_db_gain": reference["psnr_db"] - baseline["psnr_db"],
            "iou": {k: v / max(baseline["iou"][k], 1e-9) for k, v in reference["iou"].items()},
            "seconds": reference["seconds"]["total"] / max(baseline["seconds"]["total"], 1e-9),
        },
        "kerb_step_vs_none": {
            "poses": stepped["poses"],
            "iou": {k: v / max(no_step["iou"][k], 1e-9) for k, v in stepped["iou"].items()},
            "psnr_db_gain": stepped["psnr_db"] - no_step["psnr_db"],
            "seconds": stepped["seconds"]["total"] / max(no_step["seconds"]["total"], 1e-9),
        },
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_json(args.out, results, indent=1)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
