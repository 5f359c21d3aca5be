"""The segment stage (`cama segment`): semantic and lane-instance masks for every image the pipeline uses, from a
segmenter checkpoint, into the workspace's `masks/predicted/` root (never into the data set).

Images: the keyframe images of every scene the keyframes stage wrote (`keyframes/<scene>.json`) and every
key-frame (sample) camera image of the data set. They go in chunks of `batch_size` to one network call each,
in this process (one worker, or CUDA) or in a local process pool or on Ray (`executor`, `workers`); masks are
written atomically as each chunk ends. Then each camera's ego body is made one through its clips
(`segment.ego_clip`: the network's per-pixel vote united with the pixels constant through the moving clips) and
the masks that differ from it are rewritten (so is their lane-instance mask). Resumable: the manifest (written last) records the checkpoint and the
images, so a rerun with the same ones does nothing; while running, a journal (`segment.io`) lists the images
done, so a run after an interruption segments only the rest (and makes the ego bodies again: a mask already given
its body votes for that body, so a pass cut short and run again ends where one pass would, up to pixels within
`vote_share` of the threshold). A run with another checkpoint or ego setting redoes them all.
"""

import logging
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import torch

from cama_pipeline.code_version import code_version
from cama_pipeline.data import CameraImage, Dataset, DatasetError, load_dataset
from cama_pipeline.data.schema import INSTANCE_DIR, SEMANTIC_DIR, mask_relpath
from cama_pipeline.fingerprints import fingerprint
from cama_pipeline.io import atomic_write_image
from cama_pipeline.keyframes.io import read_keyframes
from cama_pipeline.progress import StageProgress
from cama_pipeline.results import ItemResult, StageResult
from cama_pipeline.segment.checkpoint import load_checkpoint, shipped_checkpoint
from cama_pipeline.segment.config import SegmentConfig
from cama_pipeline.segment.ego import estimate_ego_mask
from cama_pipeline.segment.ego_clip import EgoClipConfig, EgoVote, camera_body, with_body
from cama_pipeline.segment.instances import lane_instances
from cama_pipeline.segment.io import (
    MaskManifest,
    progress_path,
    read_mask_manifest,
    read_progress,
    write_mask_manifest,
    write_progress,
)
from cama_pipeline.segment.predict import resolve_device, segment_images
from cama_pipeline.workspace import Workspace

logger = logging.getLogger(__name__)

SOURCE = "predicted"
EXECUTORS = ("local", "ray")


@dataclass(frozen=True)
class Chunk:
    """One network call's images: what a worker needs to segment and write them (picklable)."""

    checkpoint: str
    device: str
    threads: int
    dataset_root: str
    mask_root: str
    filenames: tuple[str, ...]
    flip_average: bool


def image_filename(dataset: Dataset, path: Path) -> str:
    """An image's sample_data filename (its path under the data set root, `/`-separated)."""
    return path.relative_to(dataset.root).as_posix()


def needed_images(dataset: Dataset, workspace: Workspace) -> list[str]:
    """Filenames of the images to segment: keyframe images of the scenes the keyframes stage wrote, then every
    key-frame camera image, each once, in data set order."""
    wanted: set[str] = set()
    for scene in dataset.scenes:
        path = workspace.keyframes(scene.name)
        if path.is_file():
            for frame in read_keyframes(path).keyframes:
                wanted.update(frame.images.values())
    ordered = []
    for image in dataset.camera_images():
        if image.is_key_frame or image.token in wanted:
            ordered.append(image_filename(dataset, image.path))
    return ordered


@lru_cache(maxsize=2)
def _worker_net(checkpoint: str, device: str, threads: int) -> Any:
    """The network of a checkpoint as it runs (`SegmentationNet.for_inference`), loaded once per worker process."""
    torch.set_num_threads(threads)
    cv2.setNumThreads(1)
    return load_checkpoint(Path(checkpoint)).net.to(torch.device(device)).for_inference()


def segment_chunk(chunk: Chunk) -> tuple[str, ...]:
    """Segment one chunk's images and write their masks (atomically); returns the filenames written."""
    net = _worker_net(chunk.checkpoint, chunk.device, chunk.threads)
    images = []
    for name in chunk.filenames:
        path = Path(chunk.dataset_root) / name
        bgr = cv2.imread(str(path), cv2.IMREAD_COLOR)
        if bgr is None:
            raise DatasetError("image file cannot be read or decoded", path=path)
        images.append(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB))
    root = Path(chunk.mask_root)
    for name, (semantic, instances) in zip(
        chunk.filenames,
        segment_images(net, images, torch.device(chunk.device), flip_average=chunk.flip_average),
        strict=True,
    ):
        atomic_write_image(root / mask_relpath(SEMANTIC_DIR, name), semantic)
        atomic_write_image(root / mask_relpath(INSTANCE_DIR, name), instances.astype(np.uint16))
    return chunk.filenames


def _read_mask(path: Path) -> np.ndarray:
    """A predicted semantic mask this stage wrote ((H, W) uint8); DatasetError naming the file otherwise."""
    mask = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if mask is None or mask.ndim != 2 or mask.dtype != np.uint8:
        raise DatasetError("predicted semantic mask cannot be read as (H, W) uint8", path=path)
    return np.asarray(mask)


def camera_groups(dataset: Dataset, filenames: Sequence[str]) -> dict[str, list[CameraImage]]:
    """The images of `filenames` per camera on the car (calibrated_sensor token), in data set order."""
    wanted = set(filenames)
    groups: dict[str, list[CameraImage]] = {}
    for image in dataset.camera_images():
        if image_filename(dataset, image.path) in wanted:
            groups.setdefault(image.calibration.token, []).append(image)
    return groups


def constant_estimates(dataset: Dataset, calibration: str, config: EgoClipConfig) -> list[np.ndarray]:
    """The constant-pixel ego body of each clip of one camera (calibrated_sensor) that moves enough to give one,
    from all of the clip's images of that camera (sweeps too)."""
    estimates = []
    for scene in dataset.scenes:
        for images in scene.images.values():
            if images and images[0].calibration.token == calibration:
                estimate = estimate_ego_mask(images, config.constant)
                if estimate is not None:
                    estimates.append(estimate)
    return estimates


def make_ego_bodies(
    dataset: Dataset,
    filenames: Sequence[str],
    mask_root: Path,
    config: EgoClipConfig,
    progress: StageProgress,
) -> dict[str, int]:
    """Give every predicted mask of each camera that camera's one ego body (see `segment.ego_clip`); rewrites
    the masks that change (semantic and lane instances, atomically). Returns the body's pixel count per channel
    (the largest over the channel's cameras) for the manifest."""
    groups = camera_groups(dataset, filenames)
    bar = progress.add_task("ego body", total=len(filenames))
    sizes: dict[str, int] = {}
    for calibration, images in groups.items():
        paths = [mask_root / mask_relpath(SEMANTIC_DIR, image_filename(dataset, im.path)) for im in images]
        vote = EgoVote()
        for image, path in zip(images, paths, strict=True):
            mask = _read_mask(path)
            size = (image.calibration.height, image.calibration.width)
            if mask.shape != size:
                raise DatasetError(
                    f"predicted mask of shape {mask.shape} for a {size[1]}x{size[0]} {image.channel} image",
                    path=path,
                )
            vote.add(mask)
        body = camera_body(vote, constant_estimates(dataset, calibration, config), config.vote_share)
        channel = images[0].channel
        sizes[channel] = max(sizes.get(channel, 0), int(body.sum()))
        for image, path in zip(images, paths, strict=True):
            semantic = _read_mask(path)
            consistent = with_body(semantic, body)
            if not np.array_equal(consistent, semantic):
                name = image_filename(dataset, image.path)
                atomic_write_image(path, consistent)
                atomic_write_image(
                    mask_root / mask_relpath(INSTANCE_DIR, name), lane_instances(consistent).astype(np.uint16)
                )
            progress.advance(bar)
    return sizes


def _run_chunks(
    chunks: Sequence[Chunk], executor: str, workers: int, on_done: Callable[[Chunk], None]
) -> None:
    """Run every chunk: here (one worker or CUDA), in a local process pool, or on Ray; `on_done` as each ends."""
    if executor == "ray":
        import ray

        started = not ray.is_initialized()
        if started:
            ray.init(
                num_cpus=workers, include_dashboard=False, log_to_driver=False, logging_level=logging.WARNING
            )
        try:
            remote = ray.remote(num_cpus=1, max_retries=0)(segment_chunk)
            pending = {remote.remote(chunk): chunk for chunk in chunks}
            while pending:
                ready, _ = ray.wait(list(pending), num_returns=1)
                ray.get(ready[0])
                on_done(pending.pop(ready[0]))
        finally:
            if started:
                ray.shutdown()
        return
    if workers <= 1 or not chunks or chunks[0].device != "cpu":
        for chunk in chunks:
            segment_chunk(chunk)
            on_done(chunk)
        return
    import multiprocessing
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait

    with ProcessPoolExecutor(
        min(workers, len(chunks)), mp_context=multiprocessing.get_context("spawn")
    ) as pool:
        futures = {pool.submit(segment_chunk, chunk): chunk for chunk in chunks}
        while futures:
            finished, _ = wait(futures, return_when=FIRST_COMPLETED)
            for future in finished:
                future.result()
                on_done(futures.pop(future))


def _already_done(mask_root: Path, manifest: Path, made_with: str, overwrite: bool) -> set[str]:
    """Images whose masks are there from this checkpoint: from the journal of an interrupted run and from a
    finished run's manifest (none when `overwrite`)."""
    if overwrite:
        return set()
    done = read_progress(mask_root, made_with)
    if manifest.is_file():
        previous = read_mask_manifest(manifest)
        if previous.made_by.get("made_with") == made_with:
            done |= set(previous.images)
    return {
        name
        for name in done
        if (mask_root / mask_relpath(SEMANTIC_DIR, name)).is_file()
        and (mask_root / mask_relpath(INSTANCE_DIR, name)).is_file()
    }


def run(
    config: SegmentConfig,
    dataset_root: Path,
    workspace: Path | Workspace | None = None,
    *,
    executor: str = "local",
    workers: int = 2,
    scenes: Sequence[str] | None = None,
    overwrite: bool = False,
    show_progress: bool = True,
) -> StageResult:
    """Segment the images the pipeline uses (see the module docstring) of the scenes named in `scenes` (else of
    all) into `masks/predicted/`; one item, that folder, with the manifest as its report."""
    started = time.perf_counter()
    if executor not in EXECUTORS:
        raise ValueError(f"--executor must be one of {', '.join(EXECUTORS)}, got {executor!r}")
    if workers < 1:
        raise ValueError(f"--workers must be >= 1, got {workers}")
    ws = Workspace.resolve(workspace, Path(dataset_root))
    dataset = load_dataset(Path(dataset_root), mask_roots=(), scenes=scenes or None)
    checkpoint_dir = config.checkpoint or shipped_checkpoint()
    checkpoint = load_checkpoint(checkpoint_dir)
    device = resolve_device(config.device)
    images = needed_images(dataset, ws)
    made_with = fingerprint(
        "segment",
        code_version("cama_pipeline.segment"),
        checkpoint.digest,
        config.ego_clip.to_json(),
        config.flip_average,
    )
    digest = fingerprint(made_with, images)
    mask_root, manifest_path = ws.masks_dir(SOURCE), ws.masks_manifest(SOURCE)
    if not overwrite and manifest_path.is_file():
        previous = read_mask_manifest(manifest_path)
        if previous.fingerprint == digest:
            logger.info("predicted masks in %s up to date", mask_root)
            item = ItemResult(SOURCE, mask_root, previous.to_json(), skipped=True)
            return StageResult("segment", ws, (item,), time.perf_counter() - started)
    done = _already_done(mask_root, manifest_path, made_with, overwrite)
    todo = [name for name in images if name not in done]
    manifest_path.unlink(missing_ok=True)  # the root is incomplete until the new manifest is written
    written = set(done) & set(images)
    write_progress(mask_root, made_with, sorted(written))
    chunks = [
        Chunk(
            str(Path(checkpoint_dir).absolute()),
            device.type,
            config.threads_per_worker,
            str(dataset.root),
            str(mask_root.absolute()),
            tuple(todo[i : i + config.batch_size]),
            config.flip_average,
        )
        for i in range(0, len(todo), config.batch_size)
    ]
    logger.info("segmenting %d images (%d already done) on %s", len(todo), len(written), device)
    with StageProgress("segment", logger=logger, enabled=show_progress) as progress:
        bar = progress.add_task("images", total=len(todo))

        def finished(chunk: Chunk) -> None:
            written.update(chunk.filenames)
            write_progress(mask_root, made_with, sorted(written))
            progress.advance(bar, len(chunk.filenames))

        _run_chunks(chunks, executor, workers if device.type == "cpu" else 1, finished)
        ego_pixels = (
            make_ego_bodies(dataset, images, mask_root, config.ego_clip, progress)
            if config.ego_clip.enabled
            else None
        )
    seconds = time.perf_counter() - started
    manifest = MaskManifest(
        source=SOURCE,
        made_by={
            "command": "cama segment",
            "checkpoint": checkpoint.label,
            "checkpoint_path": str(Path(checkpoint_dir).absolute()),
            "weights_digest": checkpoint.digest,
            "flip_average": config.flip_average,
            "made_with": made_with,
        },
        images=tuple(images),
        fingerprint=digest,
        seconds=round(seconds, 2),
        extra={
            "segmented": len(todo),
            "reused": len(images) - len(todo),
            "device": device.type,
            "ego_body_pixels": ego_pixels,
        },
    )
    write_mask_manifest(manifest_path, manifest)
    progress_path(mask_root).unlink(missing_ok=True)
    item = ItemResult(SOURCE, mask_root, manifest.to_json(), skipped=False)
    return StageResult("segment", ws, (item,), seconds)
