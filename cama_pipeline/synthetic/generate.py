"""`cama synth`: generate a synthetic driving site as a nuScenes-layout data set plus its ground truth.

Output (`out_dir`):
    nuscenes/                 the data set (see cama_pipeline.data.schema), what the pipeline reads
    ground_truth/             what the pipeline is measured against, never read by it:
        vector_map.json       true elements (global metres, with z)
        baseline_map.json     a flawed 2D map (the paper's baseline)
        poses.json            true ego pose of every sample_data token
        bev/                  true BEV rasters, a raster folder (cama_pipeline.bev) with every layer
    manifest.json             config (a randomised site's drawn config, with its `random_seed`), location,
                              fingerprint and counts; written last, so its presence means complete;
                              `images_rendered` false marks a site made with `images=False` (`cama synth
                              --no-images`): every table, CAN file and ground-truth file is written, byte for byte
                              as a normal run would, but no camera image and no mask file (the tables still list
                              them, so a stage that reads images fails naming the missing file)

The whole tree is built in a sibling staging folder and renamed into place, so an interrupted run never
leaves a half-written site; a rerun with the same config finds the manifest and does nothing.
"""

import dataclasses
import hashlib
import json
import logging
import multiprocessing
import shutil
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import torch

from cama_pipeline.bev import BevRasters, write_bev
from cama_pipeline.data.schema import INSTANCE_DIR, SEMANTIC_DIR, mask_relpath
from cama_pipeline.io import atomic_write_image, atomic_write_json
from cama_pipeline.progress import StageProgress
from cama_pipeline.semantics import Semantic
from cama_pipeline.synthetic import ground_truth as gt
from cama_pipeline.synthetic.camera_effects import apply_camera_effects
from cama_pipeline.synthetic.config import SynthConfig
from cama_pipeline.synthetic.masks import degrade_masks
from cama_pipeline.synthetic.motion import TrueMotion, matrix_to_quat
from cama_pipeline.synthetic.render import render_view
from cama_pipeline.synthetic.sensors import coarse_ego_poses, simulate_can
from cama_pipeline.synthetic.site_model import SyntheticSite, build_synthetic_site, sub_rng
from cama_pipeline.synthetic.writer import NuScenesTables, image_filename, make_token, write_can

logger = logging.getLogger(__name__)

GENERATOR_VERSION = 2
"""Bump when the generator's output changes for the same config, so old sites count as out of date."""
DATASET_DIR = "nuscenes"
GROUND_TRUTH_DIR = "ground_truth"
MANIFEST = "manifest.json"
SEED_SENSORS, SEED_MASKS, SEED_CAMERA = 11, 12, 13


@dataclass(frozen=True)
class SynthResult:
    """Where a generated site is and what it holds."""

    out_dir: Path
    dataset_root: Path
    ground_truth_dir: Path
    version: str
    scenes: dict[str, str]
    """scene name -> kind (moving / stationary / night)."""
    images: int
    """Camera images the tables list (rendered or not)."""
    seconds: float
    skipped: bool
    images_rendered: bool = True
    """False for a site generated with `images=False`: its image and mask files do not exist."""


def fingerprint(cfg: SynthConfig, *, images: bool = True) -> str:
    """Hash of everything that determines the output; a site without images hashes apart from the full one,
    so that a later full run over it is never skipped as up to date."""
    content: dict[str, object] = {"config": dataclasses.asdict(cfg), "generator": GENERATOR_VERSION}
    if not images:
        content["images"] = False
    payload = json.dumps(content, sort_keys=True)
    return hashlib.sha256(payload.encode()).hexdigest()[:16]


def run(
    cfg: SynthConfig,
    out_dir: Path,
    *,
    images: bool = True,
    overwrite: bool = False,
    workers: int = 2,
    show_progress: bool = True,
) -> SynthResult:
    """Generate the site of `cfg` into `out_dir`, or do nothing if it is already there and up to date.

    `images=False` skips rendering (most of the time on big presets): tables, CAN and ground truth only, for
    work that needs poses but no pixels (the pairs benchmark); the manifest records it.
    """
    out_dir = Path(out_dir)
    existing = _read_manifest(out_dir)
    digest = fingerprint(cfg, images=images)
    if existing is not None and existing.get("fingerprint") == digest and not overwrite:
        logger.info("%s is up to date; nothing to do", out_dir)
        return _result_from_manifest(out_dir, existing, skipped=True)
    if out_dir.exists() and any(out_dir.iterdir()) and existing is None and not overwrite:
        raise FileExistsError(
            f"{out_dir} exists, is not empty and is not a generated site; pass overwrite to replace it"
        )

    started = time.perf_counter()
    staging = out_dir.parent / f".{out_dir.name}.partial"
    shutil.rmtree(staging, ignore_errors=True)
    staging.mkdir(parents=True)
    site = build_synthetic_site(cfg)
    dataset_root = staging / DATASET_DIR
    true_poses = _write_tables_and_can(site, dataset_root)
    n_images = sum(len(site.schedules[clip.index].shots) for clip in site.clips)
    if images:
        _render_all(site, dataset_root, workers, show_progress)
    else:
        logger.info("images not rendered (images=False): %d image files listed but absent", n_images)
    _write_ground_truth(site, staging / GROUND_TRUTH_DIR, true_poses, dataset_root, show_progress)
    scenes = {clip.name: clip.kind for clip in site.clips}
    manifest = {
        "fingerprint": digest,
        "preset": cfg.preset,
        "seed": cfg.seed,
        "random_seed": cfg.random_seed,
        "location": cfg.log_location,
        "version": cfg.version,
        "config": dataclasses.asdict(cfg),
        "scenes": scenes,
        "images": n_images,
        "images_rendered": images,
        "seconds": round(time.perf_counter() - started, 2),
    }
    atomic_write_json(staging / MANIFEST, manifest, indent=2)
    _swap_into_place(staging, out_dir)
    return _result_from_manifest(out_dir, manifest, skipped=False)


def _read_manifest(out_dir: Path) -> dict | None:
    path = out_dir / MANIFEST
    if not path.is_file():
        return None
    try:
        return json.loads(path.read_text())
    except json.JSONDecodeError:
        return None


def _result_from_manifest(out_dir: Path, manifest: dict, *, skipped: bool) -> SynthResult:
    return SynthResult(
        out_dir,
        out_dir / DATASET_DIR,
        out_dir / GROUND_TRUTH_DIR,
        manifest["version"],
        manifest["scenes"],
        manifest["images"],
        manifest["seconds"],
        skipped,
        bool(manifest.get("images_rendered", True)),
    )


def _swap_into_place(staging: Path, out_dir: Path) -> None:
    """Replace `out_dir` by the finished staging tree (the old tree is removed only after the rename)."""
    if out_dir.exists():
        retired = out_dir.parent / f".{out_dir.name}.old"
        shutil.rmtree(retired, ignore_errors=True)
        out_dir.rename(retired)
        staging.rename(out_dir)
        shutil.rmtree(retired, ignore_errors=True)
    else:
        staging.rename(out_dir)


def _global_motion(motion: TrueMotion, origin_xy: tuple[float, float]) -> TrueMotion:
    """The same motion with positions in global coordinates."""
    shift = np.array([origin_xy[0], origin_xy[1], 0.0])
    return TrueMotion(motion.times_us, motion.global_from_ego_R, motion.global_from_ego_t + shift)


def _log_name(site: SyntheticSite, clip_index: int) -> str:
    clip = site.clips[clip_index]
    return f"synth-{site.config.preset}-{clip.index + 1:04d}-{clip.kind}"


def _description(site: SyntheticSite, clip_index: int) -> str:
    clip = site.clips[clip_index]
    if clip.kind == "stationary":
        return "Day, stationary, waiting at the junction"
    return f"{'Night' if clip.kind == 'night' else 'Day'}, moving, route {clip.route_name}"


def _write_tables_and_can(site: SyntheticSite, dataset_root: Path) -> dict[str, dict]:
    """nuScenes tables with coarse ego poses, CAN messages per scene; returns the true pose per sample_data."""
    cfg = site.config
    tables = NuScenesTables(location=cfg.log_location)
    tables.add_rig(site.rig)
    true_poses: dict[str, dict] = {}
    for clip in site.clips:
        schedule = site.schedules[clip.index]
        motion = _global_motion(clip.motion, cfg.site_origin_xy)
        times = np.array([s.timestamp_us for s in schedule.shots])
        rng = sub_rng(cfg.seed, SEED_SENSORS, clip.index)
        coarse_R, coarse_t = coarse_ego_poses(motion, times, cfg.sensors, rng)
        true_R, true_t = motion.interpolate(times)
        tables.add_clip(
            clip.name,
            _log_name(site, clip.index),
            _description(site, clip.index),
            clip.start_time_us,
            schedule.sample_times_us,
            schedule.shots,
            coarse_R,
            coarse_t,
            (cfg.camera.width_px, cfg.camera.height_px),
        )
        write_can(dataset_root, clip.name, simulate_can(motion, cfg.sensors, rng))
        for i, shot in enumerate(schedule.shots):
            token = make_token(clip.name, "sample_data", shot.channel, shot.sweep_index)
            true_poses[token] = {
                "scene": clip.name,
                "channel": shot.channel,
                "timestamp": shot.timestamp_us,
                "is_key_frame": shot.is_key_frame,
                "rotation": [float(q) for q in matrix_to_quat(true_R[i])],
                "translation": [float(v) for v in true_t[i]],
            }
    tables.add_map("maps/drivable_area.png")
    tables.write(dataset_root / cfg.version)
    return true_poses


# ---- rendering, in worker processes that rebuild the site from its config --------------------------

_WORKER_SITE: SyntheticSite | None = None


def _init_worker(cfg: SynthConfig) -> None:
    global _WORKER_SITE
    torch.set_num_threads(1)
    cv2.setNumThreads(1)
    _WORKER_SITE = build_synthetic_site(cfg)


def render_shot(site: SyntheticSite, clip_index: int, shot_index: int, dataset_root: Path) -> None:
    """Render one camera image and write it with its semantic and instance masks."""
    clip = site.clips[clip_index]
    shot = site.schedules[clip_index].shots[shot_index]
    view, R_ego, t_ego = site.view(clip_index, shot_index)
    boxes = site.boxes_at(clip_index, shot.timestamp_us, R_ego, t_ego)
    rendering = render_view(
        site.world, view, boxes, night=clip.kind == "night", exposure=site.exposures[clip_index]
    )
    rng = sub_rng(site.config.seed, SEED_MASKS, clip_index, shot_index)
    rgb = rendering.rgb
    if clip.kind == "night":
        rgb = rgb + rng.normal(0.0, 0.012, size=rgb.shape).astype(np.float32)
    camera_rng = sub_rng(site.config.seed, SEED_CAMERA, clip_index, shot_index)
    rgb = apply_camera_effects(rgb, site.config.camera, camera_rng)
    semantic, instance = degrade_masks(rendering.semantic, rendering.instance, site.config.masks, rng)
    filename = image_filename(_log_name(site, clip_index), shot)
    bgr = cv2.cvtColor((np.clip(rgb, 0, 1) * 255 + 0.5).astype(np.uint8), cv2.COLOR_RGB2BGR)
    atomic_write_image(dataset_root / filename, bgr, jpeg_quality=site.config.camera.jpeg_quality)
    atomic_write_image(dataset_root / mask_relpath(SEMANTIC_DIR, filename), semantic)
    atomic_write_image(dataset_root / mask_relpath(INSTANCE_DIR, filename), instance.astype(np.uint16))


def _render_task(task: tuple[int, int, str]) -> None:
    if _WORKER_SITE is None:
        raise RuntimeError("render worker used before its initialiser ran")
    render_shot(_WORKER_SITE, task[0], task[1], Path(task[2]))


def _tasks(site: SyntheticSite, dataset_root: Path) -> Iterator[tuple[int, int, str]]:
    for clip in site.clips:
        for shot_index in range(len(site.schedules[clip.index].shots)):
            yield clip.index, shot_index, str(dataset_root)


def _render_all(site: SyntheticSite, dataset_root: Path, workers: int, show_progress: bool) -> None:
    """Render every shot of every clip, in `workers` processes (1 = in this process)."""
    tasks = list(_tasks(site, dataset_root))
    with StageProgress("synthetic", logger=logger, enabled=show_progress) as progress:
        bar = progress.add_task("render images", total=len(tasks))
        if workers <= 1:
            for clip_index, shot_index, root in tasks:
                render_shot(site, clip_index, shot_index, Path(root))
                progress.advance(bar)
        else:
            context = multiprocessing.get_context("spawn")
            with context.Pool(workers, initializer=_init_worker, initargs=(site.config,)) as pool:
                for _ in pool.imap_unordered(_render_task, tasks, chunksize=4):
                    progress.advance(bar)
                pool.close()  # let the workers exit: the with-block's terminate() SIGTERMs them mid-exit, and
                pool.join()  # a native library's signal handler then prints a stack trace into the user's terminal


# ---- ground truth ----------------------------------------------------------------------------------


def _key_frame_cameras(site: SyntheticSite) -> list[tuple[np.ndarray, np.ndarray, np.ndarray, int, int]]:
    cameras = []
    for clip in site.clips:
        for i, shot in enumerate(site.schedules[clip.index].shots):
            if shot.is_key_frame:
                view, _, _ = site.view(clip.index, i)
                cameras.append(
                    (view.layout_from_cam_R, view.layout_from_cam_t, view.K, view.width_px, view.height_px)
                )
    return cameras


def _write_ground_truth(
    site: SyntheticSite, gt_dir: Path, true_poses: dict[str, dict], dataset_root: Path, show_progress: bool
) -> None:
    """Vector map, baseline map, true poses and BEV rasters; also the data set's drivable-area prior."""
    cfg = site.config
    with StageProgress("synthetic ground truth", logger=logger, enabled=show_progress) as progress:
        bar = progress.add_task("vector maps", total=4)
        vectors = gt.vector_map(site.layout, site.world, cfg.site_origin_xy)
        atomic_write_json(gt_dir / "vector_map.json", {"elements": vectors})
        baseline = gt.baseline_map(site.layout, cfg.site_origin_xy, sub_rng(cfg.seed, 21))
        atomic_write_json(gt_dir / "baseline_map.json", baseline)
        atomic_write_json(gt_dir / "poses.json", true_poses)
        progress.update(bar, advance=1, description="BEV rasters")
        grid = gt.bev_grid_for(site.world, cfg.bev_resolution_m)
        semantic, photometric, elevation = gt.render_bev(site.world, grid)
        progress.update(bar, advance=1, description="observation count")
        count = gt.observation_count(grid, elevation, _key_frame_cameras(site))
        progress.update(bar, advance=1, description="writing rasters")
        write_bev(
            gt_dir / "bev",
            BevRasters(
                grid.georeference(cfg.site_origin_xy),
                semantic=gt.unobserved_to_255(semantic, count),
                photometric_rgb=photometric,
                elevation=elevation,
                observation_count=count,
            ),
        )
        drivable = np.isin(
            semantic, [int(Semantic.ROAD), int(Semantic.LANE_MARKING), int(Semantic.CROSSWALK)]
        )
        atomic_write_image(dataset_root / "maps" / "drivable_area.png", drivable.astype(np.uint8) * 255)
        progress.update(bar, advance=1, description="written")
