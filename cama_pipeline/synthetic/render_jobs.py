"""Rendering the camera images of a site and their masks, in worker processes that rebuild the site from its
config (so that no large arrays cross process boundaries and any worker count gives the same bytes)."""

import logging
import multiprocessing
from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np
import torch

from cama_pipeline.data.schema import INSTANCE_DIR, SEMANTIC_DIR, mask_relpath
from cama_pipeline.io import atomic_write_image
from cama_pipeline.progress import StageProgress
from cama_pipeline.synthetic.camera_effects import apply_camera_effects
from cama_pipeline.synthetic.config import SynthConfig
from cama_pipeline.synthetic.masks import degrade_masks
from cama_pipeline.synthetic.render import render_view
from cama_pipeline.synthetic.site_model import SyntheticSite, build_synthetic_site, sub_rng
from cama_pipeline.synthetic.writer import image_filename

logger = logging.getLogger(__name__)

SEED_MASKS, SEED_CAMERA = 12, 13
"""Sub-seeds of the per-shot night noise and mask degradation, and of the camera's blur and noise."""

_WORKER_SITE: SyntheticSite | None = None


def _init_worker(cfg: SynthConfig) -> None:
    global _WORKER_SITE
    torch.set_num_threads(1)
    cv2.setNumThreads(1)
    _WORKER_SITE = build_synthetic_site(cfg)


def render_shot(
    site: SyntheticSite, clip_index: int, shot_index: int, dataset_root: Path, mask_root: Path | None = None
) -> None:
    """Render one camera image into `dataset_root` and write its semantic and instance masks under `mask_root`
    (`<mask_root>/semantic/<image path>.png`, `<mask_root>/lane_instance/...`; the data set's own root when
    None)."""
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
    filename = image_filename(site.log_name(clip_index), shot)
    bgr = cv2.cvtColor((np.clip(rgb, 0, 1) * 255 + 0.5).astype(np.uint8), cv2.COLOR_RGB2BGR)
    atomic_write_image(dataset_root / filename, bgr, jpeg_quality=site.config.camera.jpeg_quality)
    masks_to = dataset_root if mask_root is None else mask_root
    atomic_write_image(masks_to / mask_relpath(SEMANTIC_DIR, filename), semantic)
    atomic_write_image(masks_to / mask_relpath(INSTANCE_DIR, filename), instance.astype(np.uint16))


def _render_task(task: tuple[int, int, str, str]) -> None:
    if _WORKER_SITE is None:
        raise RuntimeError("render worker used before its initialiser ran")
    render_shot(_WORKER_SITE, task[0], task[1], Path(task[2]), Path(task[3]))


def _tasks(site: SyntheticSite, dataset_root: Path, mask_root: Path) -> Iterator[tuple[int, int, str, str]]:
    for clip in site.clips:
        for shot_index in range(len(site.schedules[clip.index].shots)):
            yield clip.index, shot_index, str(dataset_root), str(mask_root)


def render_all(
    site: SyntheticSite, dataset_root: Path, mask_root: Path, workers: int, show_progress: bool
) -> None:
    """Render every shot of every clip (images into `dataset_root`, masks under `mask_root`), in `workers`
    processes (1 = in this process); one image at a time per process, so memory does not grow with the site."""
    tasks = list(_tasks(site, dataset_root, mask_root))
    with StageProgress("synthetic", logger=logger, enabled=show_progress) as progress:
        bar = progress.add_task("render images", total=len(tasks))
        if workers <= 1:
            for clip_index, shot_index, root, masks_to in tasks:
                render_shot(site, clip_index, shot_index, Path(root), Path(masks_to))
                progress.advance(bar)
        else:
            context = multiprocessing.get_context("spawn")
            with context.Pool(workers, initializer=_init_worker, initargs=(site.config,)) as pool:
                for _ in pool.imap_unordered(_render_task, tasks, chunksize=4):
                    progress.advance(bar)
                pool.close()  # let the workers exit: the with-block's terminate() SIGTERMs them mid-exit, and
                pool.join()  # a native library's signal handler then prints a stack trace into the user's terminal
