"""End-to-end benchmark: the whole path on a synthetic site, measured against the truth the generator kept.

1. `cama run` (wigo ... surface -> proposals) into the site's workspace; seconds per stage of this run (a stage
   that was already up to date shows the time of its skip check; its own report's timings are listed too), the
   same per keyframe of the site (to compare image sizes and site sizes), and the peak resident memory of this
   process and of its worker processes (the pipeline streams images; a 1600x900 site must fit the machine).
2. Camera pose error of the coarse WIGO poses and of the SfM poses against the true poses (absolute,
   gauge-free after the best similarity of the whole site, and per clip after each scene's own similarity: WIGO
   fuses each clip alone, so without logged heights its clips sit at different heights and one similarity for
   all of them reports their offsets as a tilt).
3. Elevation RMSE of the reconstructed raster over cells that are road in the ground truth and observed.
4. Which model proposed (`proposed_by`: the elements' authors, e.g. `vma-masks-v0004`), and Chamfer-AP (0.5 / 1.0 /
   1.5 m) of the VMA proposals against the true vectors inside the reconstructed extent,
   and against the true vectors cut to the observed cells (the clips drove only part of the generated roads).
5. The paper's comparison table on known truth: SRE / precision / recall / F1 of lane dividers against the image
   lane masks for (a) the true 3D map with true poses, (b) the baseline 2D map with coarse poses, (c1) the
   pipeline's proposals accepted as they are and (c2) the pipeline's annotations after the simulated annotator's
   correction pass; (c) are lifted through the reconstructed elevation and projected with the SfM poses.
   Each row records `sre_ref_px`, the SRE at 960x540 (the paper's and CAMA's scale; the figure README quotes and
   the plot shows), beside `sre_px` in the images' own pixels (512 wide on the synthetic sites).
6. The simulated annotator's person-hours per km: drawing from scratch vs correcting the proposals, on the true
   vectors cut to the observed cells (nobody can draw road that no camera saw): `annotator` towards the truth where
   the world has it, `annotator_in_reconstruction_frame` towards the truth carried into the frame the rasters sit in
   (`reconstruction_frame`: the 2D similarity from the true to the reconstruction's keyframe positions, how far it
   moves them and what it leaves; see `cama_pipeline.evaluate.frame`), which is what an annotator looking at the
   rasters and images can reach.

Plots (per-stage time, SRE / F1 comparison, elevation error map, observation-count map) go to
bench/results/end_to_end/*.png; figures to bench/results/end_to_end.json (`--out X.json`: X.json and X/*.png).

Usage: .venv/bin/python bench/end_to_end.py [--site data/synthetic/default] [--proposer learned|masks|rule]
       [--checkpoint REGISTRY_OR_VERSION]
       [--masks auto|dataset|predicted|DIR] [--first-octave N] [--out bench/results/end_to_end.json] [--measure-only]
       [--workspace DIR (default: the data set's)]
"""

import argparse
import json
import logging
import platform
import resource
import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import matplotlib
import numpy as np
from scipy.spatial.transform import Rotation

from annotations.lift import lift_points
from annotations.schema import AnnotationSet, Georeference
from app.review_effort.truth import observed_true_polylines
from app.simulation.annotator import correct_proposals, draw_from_scratch
from app.simulation.workbench import kept_map, load_proposals, local_backend, register_synthetic_site
from cama_pipeline.bev import read_bev, read_layer
from cama_pipeline.cameras import CameraView, site_views
from cama_pipeline.data import Pose, load_dataset
from cama_pipeline.evaluate import SreConfig, evaluate_sre, load_true_poses, load_vector_map
from cama_pipeline.evaluate.frame import ReconstructionFrame, reconstruction_frame
from cama_pipeline.evaluate.inputs import VectorElement
from cama_pipeline.evaluate.observed import ObservedMask, observed_parts
from cama_pipeline.features.config import FeaturesConfig
from cama_pipeline.semantics import Semantic
from cama_pipeline.sfm.baseline import aligned_poses, pose_errors
from cama_pipeline.sfm.io import read_refined_poses
from cama_pipeline.site.io import read_site_manifest
from cama_pipeline.synthetic.generate import truth_dataset
from cama_pipeline.synthetic.truth_grid import truth_on_grid
from cama_pipeline.workspace import Workspace
from cama_studio.config import PipelineConfig
from cama_studio.pipeline import run as run_pipeline
from models.vma.checkpoint import ensure_unseen, load_checkpoint
from models.vma.element_masks.checkpoint import load_mask_checkpoint
from models.vma.evaluate import evaluate_sites
from models.vma.rasters import load_site_rasters
from models.vma.shipped import SHIPPED_MASK_REGISTRY, resolve_checkpoint
from models.vma.vectors import Vector, read_vectors, vectors_from_annotations

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

RESULTS = Path(__file__).parent / "results"
logger = logging.getLogger("bench.end_to_end")


def stage_reports(workspace: Workspace, site_id: str) -> dict[str, Any]:
    """Timings the stages wrote into their own reports (the run that made the outputs)."""
    found: dict[str, Any] = {}
    for stage, path in {
        "features": workspace.features_report(site_id),
        "sfm": workspace.sfm_report(site_id),
        "surface": workspace.surface_report(site_id),
    }.items():
        if path.is_file():
            report = json.loads(path.read_text())
            found[stage] = report.get("seconds")
    return found


def keyframe_count(workspace: Workspace, site_id: str) -> int:
    """Keyframes (frames of six images) the site's reconstruction uses, over all its scenes."""
    manifest = read_site_manifest(workspace.site_manifest(site_id))
    return sum(1 for scene in manifest["scenes"] for frame in scene["frames"] if frame["keyframe"])


def peak_memory_mb() -> dict[str, float]:
    """Peak resident set size of this process and of the largest finished child process, in MB (Linux kB)."""
    own = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    children = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
    return {"self_mb": round(own, 1), "largest_child_mb": round(children, 1)}


def per_clip_aligned(
    poses: dict[str, np.ndarray], truth: dict[str, np.ndarray], scene_of: dict[str, str]
) -> dict[str, np.ndarray]:
    """`poses` with each scene's images moved by that scene's own best similarity onto the truth."""
    moved: dict[str, np.ndarray] = {}
    for scene in sorted(set(scene_of.values())):
        clip = {name: pose for name, pose in poses.items() if scene_of[name] == scene}
        moved.update(aligned_poses(clip, truth))
    return moved


def pose_figures(site: Path, views: list[CameraView], workspace: Workspace, site_id: str) -> dict[str, Any]:
    """WIGO and SfM camera pose errors against the truth."""
    truth_poses = load_true_poses(site / "ground_truth" / "poses.json")
    truth = {v.name: truth_poses[v.token].matrix() @ v.ego_from_cam for v in views}
    wigo = {v.name: v.world_from_cam for v in views}
    refined = read_refined_poses(workspace.sfm_poses(site_id))
    sfm = {v.name: refined[v.token] @ v.ego_from_cam for v in views if v.token in refined}
    scene_of = {v.name: v.scene for v in views}
    out = {}
    for name, poses in (("wigo", wigo), ("sfm", sfm)):
        absolute = pose_errors(poses, truth)
        gauge_free = pose_errors(aligned_poses(poses, truth), truth)
        per_clip = pose_errors(per_clip_aligned(poses, truth, scene_of), truth)
        out[name] = {
            "position_cm": absolute.position_cm,
            "rotation_deg": absolute.rotation_deg,
            "registered_ratio": absolute.registered_ratio,
            "gauge_free_position_cm": gauge_free.position_cm,
            "gauge_free_rotation_deg": gauge_free.rotation_deg,
            "per_clip_gauge_free_position_cm": per_clip.position_cm,
            "per_clip_gauge_free_rotation_deg": per_clip.rotation_deg,
        }
    return out


def elevation_figures(site: Path, folder: Path) -> tuple[dict[str, Any], np.ndarray]:
    """RMSE of the reconstructed elevation over observed cells that are road in the truth; the error map.
    The truth is rendered on the reconstruction's own grid, as `bench/surface.py` scores it."""
    ours = read_bev(folder)
    truth = truth_on_grid(site, ours.georeference)
    elevation = ours.require("elevation").astype(np.float64)
    true_sem = truth.require("semantic")
    road = (true_sem >= int(Semantic.ROAD)) & (true_sem != int(Semantic.UNOBSERVED))
    observed = (ours.require("semantic") != int(Semantic.UNOBSERVED)) & np.isfinite(elevation)
    use = road & observed
    error = np.full(elevation.shape, np.nan)
    error[use] = elevation[use] - truth.require("elevation")[use]
    values = error[use]
    figures = {
        "cells": int(use.sum()),
        "rmse_cm": float(np.sqrt(np.mean(values**2)) * 100) if values.size else None,
        "median_abs_cm": float(np.median(np.abs(values)) * 100) if values.size else None,
        "p95_abs_cm": float(np.percentile(np.abs(values), 95) * 100) if values.size else None,
    }
    return figures, error


def proposal_vectors(path: Path) -> list[Any]:
    return vectors_from_annotations(
        AnnotationSet.read_json(path), ("proposed", "accepted", "fixed", "approved")
    )


def observed_mask(rasters_folder: Path) -> ObservedMask:
    bev = read_bev(rasters_folder, ["semantic"])
    geo = bev.georeference
    return ObservedMask.from_semantic(bev.require("semantic"), geo.origin_xy, geo.resolution)


def observed_truth(truths: list[Vector], mask: ObservedMask) -> list[Vector]:
    """The true vectors cut to the observed cells."""
    return [
        Vector(t.cls, part)
        for t in truths
        for part in observed_parts(t.points, t.cls == "ped_crossing", mask)
    ]


def proposals_ap(site: Path, rasters_folder: Path, proposals: Path) -> dict[str, Any]:
    """Chamfer-AP of the proposals against the true vectors inside the reconstructed extent: all of them, and
    only their observed parts."""
    extent = load_site_rasters(rasters_folder).extent()
    truths = read_vectors(site / "ground_truth" / "vector_map.json")
    out = {}
    for name, truth in (
        ("all_truth", truths),
        ("observed_truth", observed_truth(truths, observed_mask(rasters_folder))),
    ):
        result = evaluate_sites([(proposal_vectors(proposals), truth, extent)])
        out[name] = {key: result[key] for key in ("mean_ap", "class_ap", "confidence_bins") if key in result}
    return out


def lifted_map(vectors_xy: list[tuple[str, np.ndarray]], folder: Path) -> list[VectorElement]:
    """2D global vectors lifted through a raster folder's elevation (vertices without elevation dropped)."""
    bev = read_bev(folder, ["semantic", "elevation"])
    geo = Georeference.of(bev.georeference, site_origin_xy=(0.0, 0.0))
    elevation = bev.require("elevation").astype(np.float64)
    unobserved = bev.require("semantic") == int(Semantic.UNOBSERVED)
    out = []
    for k, (cls, points) in enumerate(vectors_xy):
        lifted = lift_points(points, elevation, geo, unobserved=unobserved, search_radius_m=2.0).points_3d
        lifted = lifted[np.isfinite(lifted[:, 2])]
        if len(lifted) >= 2:
            out.append(VectorElement(f"v{k}", cls, lifted, cls == "ped_crossing"))
    return out


def sfm_pose_map(workspace: Workspace, site_id: str) -> dict[str, Pose]:
    """SfM world_from_ego by image token, as the SRE evaluation takes poses."""
    out = {}
    for token, matrix in read_refined_poses(workspace.sfm_poses(site_id)).items():
        quaternion = Rotation.from_matrix(matrix[:3, :3]).as_quat(scalar_first=True)
        out[token] = Pose(matrix[:3, 3], quaternion)
    return out


def simulated_pass(
    site: Path, proposals: Path, rasters_folder: Path, frame: ReconstructionFrame | None = None
) -> tuple[dict[str, Any], list[tuple[str, np.ndarray]]]:
    """The scripted annotator on the proposals and on an empty site, both working towards the observed parts of
    the true vectors (carried into `frame`, None: the world's); the corrected map (global 2D)."""
    truths = observed_true_polylines(site, load_site_rasters(rasters_folder), frame)
    with local_backend(site) as (admin, annotator):
        corrected_site = register_synthetic_site(admin, site, "corrected")
        load_proposals(admin, corrected_site, proposals)
        corrected = correct_proposals(annotator, corrected_site, truths)
        scratch = draw_from_scratch(annotator, register_synthetic_site(admin, site, "scratch"), truths)
        kept = kept_map(annotator, corrected_site)
    figures = {
        "scratch": scratch.as_dict(),
        "corrected": corrected.as_dict(),
        "speed_up": scratch.total_s / corrected.total_s if corrected.total_s else None,
    }
    return figures, kept


def sre_rows(
    site: Path,
    workspace: Workspace,
    site_id: str,
    rows: dict[str, tuple[list[VectorElement], dict | None]],
    images: set[str],
) -> dict[str, Any]:
    """SRE / precision / recall / F1 of each map over the same images: the site's key-frame images SfM posed."""
    dataset = truth_dataset(site)
    config = SreConfig(class_pairs=(("divider", int(Semantic.LANE_MARKING)),))
    scenes = [s["scene"] for s in read_site_manifest(workspace.site_manifest(site_id))["scenes"]]
    out = {}
    for name, (elements, poses) in rows.items():
        report = evaluate_sre(dataset, elements, config, true_poses=poses, scenes=scenes, images=images)
        out[name] = {k: v for k, v in vars(report.overall).items()}
    return out


def cropped(image: np.ndarray) -> np.ndarray:
    """The image cut to the bounding box of its finite cells (a site's rasters are mostly unobserved)."""
    rows, cols = np.nonzero(np.isfinite(image))
    if rows.size == 0:
        return image
    return image[rows.min() : rows.max() + 1, cols.min() : cols.max() + 1]


def raster_plot(plots_dir: Path, name: str, image: np.ndarray, title: str, label: str, **style: Any) -> str:
    """One raster (cropped to its finite cells) with a colour bar, saved in `plots_dir`; its file name."""
    fig, ax = plt.subplots(figsize=(6, 5))
    shown = ax.imshow(cropped(image), **style)
    fig.colorbar(shown, ax=ax, label=label)
    ax.set_title(title)
    ax.set_axis_off()
    fig.tight_layout()
    fig.savefig(plots_dir / name, dpi=110)
    return name


def sre_plot(sre: dict[str, Any], plots_dir: Path) -> str:
    """SRE at 960x540 (`sre_ref_px`) and F1 of each map, saved in `plots_dir`; its file name."""
    names = list(sre)
    fig, axes = plt.subplots(1, 2, figsize=(9, 3.5))
    axes[0].bar(names, [sre[n]["sre_ref_px"] for n in names], color="#f87171")
    axes[0].set_title("SRE at 960x540 (px, lower is better)")
    axes[1].bar(names, [sre[n]["f1"] for n in names], color="#22c55e")
    axes[1].set_title("F1 (higher is better)")
    for ax in axes:
        ax.tick_params(axis="x", rotation=20)
    fig.tight_layout()
    fig.savefig(plots_dir / "sre_f1.png", dpi=110)
    return "sre_f1.png"


def sre_lines(sre: dict[str, Any]) -> list[str]:
    """The SRE rows as printed: SRE at 960x540 (`sre_ref_px`) first, the images' own pixels after it."""
    return [
        f"{name}: SRE {row['sre_ref_px']:.2f} px at 960x540 ({row['sre_px']:.2f} px at the images' own width),"
        f" precision {row['precision']:.2f}, recall {row['recall']:.2f}, F1 {row['f1']:.2f}"
        for name, row in sre.items()
    ]


def plots(figures: dict[str, Any], error_map: np.ndarray, rasters_folder: Path, plots_dir: Path) -> list[str]:
    plots_dir.mkdir(parents=True, exist_ok=True)
    written = []
    stages = dict(figures["stage_seconds"])
    for stage, seconds in figures["stage_reports"].items():  # a skipped stage: the run that made its outputs
        if isinstance(seconds, dict) and stages.get(stage, 0.0) < 1.0:
            stages[stage] = sum(v for k, v in seconds.items() if k != "total")
    fig, ax = plt.subplots(figsize=(7, 3.5))
    ax.bar(list(stages), list(stages.values()), color="#38bdf8")
    ax.set_ylabel("seconds (stage reports where skipped)")
    ax.set_title("Time per stage")
    fig.tight_layout()
    fig.savefig(plots_dir / "stage_seconds.png", dpi=110)
    written.append("stage_seconds.png")
    written.append(sre_plot(figures["sre"], plots_dir))
    written.append(
        raster_plot(
            plots_dir,
            "elevation_error.png",
            error_map * 100,
            "Elevation error on road cells",
            "reconstructed - true elevation (cm)",
            cmap="coolwarm",
            vmin=-10,
            vmax=10,
        )
    )
    counts = read_layer(rasters_folder, "observation_count").astype(float)
    written.append(
        raster_plot(
            plots_dir,
            "observation_count.png",
            np.where(counts > 0, counts, np.nan),
            "Observation count",
            "camera rays per cell",
            cmap="viridis",
        )
    )
    plt.close("all")
    return written


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--site", type=Path, default=Path("data/synthetic/default"))
    parser.add_argument("--site-id", default="site-001")
    parser.add_argument("--proposer", choices=("learned", "masks", "rule"), default="learned")
    parser.add_argument(
        "--checkpoint",
        type=Path,
        default=None,
        help="VMA registry or version folder to propose with (default: the shipped one of the proposer's kind)",
    )
    parser.add_argument("--max-features", type=int, default=None)
    parser.add_argument(
        "--first-octave",
        type=int,
        default=None,
        help="SIFT's first octave for every image (default: the product's per-width choice, FeaturesConfig)",
    )
    parser.add_argument(
        "--masks",
        default="auto",
        help="the run's mask choice (cama run --masks): auto, dataset, predicted, DIR",
    )
    parser.add_argument(
        "--out", type=Path, default=RESULTS / "end_to_end.json", help="figures JSON (plots beside)"
    )
    parser.add_argument(
        "--measure-only",
        action="store_true",
        help="measure the workspace as it is, without running the pipeline (its proposals must exist)",
    )
    parser.add_argument(
        "--workspace",
        type=Path,
        default=None,
        help="the workspace to run into and measure (default: the data set's, SITE/workspace)",
    )
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)
    site, site_id = args.site, args.site_id
    if args.proposer == "learned":  # SeenSiteError when the VMA model trained on this site
        ensure_unseen(load_checkpoint(resolve_checkpoint(args.checkpoint)), site)
    if args.proposer == "masks":  # the same for the element-mask network
        ensure_unseen(load_mask_checkpoint(resolve_checkpoint(args.checkpoint, SHIPPED_MASK_REGISTRY)), site)
    workspace = Workspace.resolve(args.workspace, site / "nuscenes")
    stage_seconds: dict[str, float] = {}
    if not args.measure_only:
        features = FeaturesConfig(first_octave=args.first_octave)
        if args.max_features is not None:
            features = replace(features, max_num_features=args.max_features)
        result = run_pipeline(
            site / "nuscenes",
            workspace.root,
            PipelineConfig(
                proposer=args.proposer, checkpoint=args.checkpoint, features=features, masks=args.masks
            ),
            on_stage=lambda s: print(f"== {s}", flush=True),
        )
        stage_seconds = {k: round(v, 1) for k, v in result.seconds.items()}
    dataset = load_dataset(site / "nuscenes")
    views = site_views(dataset, read_site_manifest(workspace.site_manifest(site_id)))
    rasters = workspace.surface_bev(site_id)
    proposals = workspace.proposals(site_id)
    keyframes = keyframe_count(workspace, site_id)
    figures: dict[str, Any] = {
        "site": str(site),
        "site_id": site_id,
        "proposer": args.proposer,
        "masks": args.masks,
        "first_octave": "per width" if args.first_octave is None else args.first_octave,
        "stage_seconds": stage_seconds,
        "keyframes": keyframes,
        "stage_seconds_per_keyframe": {
            stage: round(seconds / max(keyframes, 1), 3) for stage, seconds in stage_seconds.items()
        },
        "peak_memory": peak_memory_mb(),
        "stage_reports": stage_reports(workspace, site_id),
        "poses": pose_figures(site, views, workspace, site_id),
    }
    figures["elevation"], error_map = elevation_figures(site, rasters)
    figures["proposed_by"] = sorted({e.author for e in AnnotationSet.read_json(proposals).elements})
    figures["proposals_ap"] = proposals_ap(site, rasters, proposals)
    figures["annotator"], corrected = simulated_pass(site, proposals, rasters)
    frame = reconstruction_frame(site / "nuscenes", workspace, site_id)
    figures["reconstruction_frame"] = frame.as_dict()
    figures["annotator_in_reconstruction_frame"], _ = simulated_pass(site, proposals, rasters, frame)
    truth = site / "ground_truth"
    sfm_poses = sfm_pose_map(workspace, site_id)
    proposal_xy = [(v.cls, v.points) for v in proposal_vectors(proposals)]
    figures["sre"] = sre_rows(
        site,
        workspace,
        site_id,
        {
            "a_truth": (load_vector_map(truth / "vector_map.json"), load_true_poses(truth / "poses.json")),
            "b_baseline_2d": (load_vector_map(truth / "baseline_map.json"), None),
            "c1_proposals": (lifted_map(proposal_xy, rasters), sfm_poses),
            "c2_corrected": (lifted_map(corrected, rasters), sfm_poses),
        },
        set(sfm_poses),
    )
    plots_dir = args.out.with_suffix("")
    figures["plots"] = plots(figures, error_map, rasters, plots_dir)
    figures["command"] = "python bench/end_to_end.py " + " ".join(sys.argv[1:])
    figures["machine"] = {"python": platform.python_version(), "time": time.strftime("%Y-%m-%d %H:%M")}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(figures, indent=1, default=float) + "\n")
    print(
        json.dumps({k: figures[k] for k in ("stage_seconds", "poses", "elevation")}, indent=1, default=float)
    )
    print("\n".join(sre_lines(figures["sre"])))
    print(f"wrote {args.out} and {plots_dir}/")


if __name__ == "__main__":
    main()
