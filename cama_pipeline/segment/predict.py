"""Running a segmenter checkpoint: the device to run on, masks for images, and per-class IoU against the
generator's masks (what a checkpoint records of its held-out sites, and what `bench/segment.py` measures)."""

import logging
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch

from cama_pipeline.data import CameraImage
from cama_pipeline.segment.checkpoint import Checkpoint, ensure_unseen
from cama_pipeline.segment.config import DeviceName
from cama_pipeline.segment.instances import lane_instances
from cama_pipeline.segment.network import IMAGE_CLASSES, NUM_CLASSES, SegmentationNet
from cama_pipeline.site_identity import site_identity
from cama_pipeline.synthetic.generate import DATASET_DIR, GROUND_TRUTH_DIR, truth_dataset

logger = logging.getLogger(__name__)


def resolve_device(device: DeviceName | str) -> torch.device:
    """`auto`: CUDA when present, else the CPU; `cuda` without CUDA is a ValueError naming `--device`."""
    if device == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if device == "cuda" and not torch.cuda.is_available():
        raise ValueError("--device cuda: this machine's torch sees no CUDA device; use --device cpu or auto")
    if device not in ("cpu", "cuda"):
        raise ValueError(f"--device must be auto, cpu or cuda, got {device!r}")
    return torch.device(device)


def segment_images(
    net: SegmentationNet, images: Sequence[np.ndarray], device: torch.device, *, flip_average: bool = False
) -> list[tuple[np.ndarray, np.ndarray]]:
    """(semantic uint8, lane instance uint16) masks of RGB uint8 images, in one network call per image size
    (two with `flip_average`: `SegmentationNet.predict`)."""
    semantic = net.predict(list(images), device, flip_average=flip_average)
    return [(labels, lane_instances(labels)) for labels in semantic]


def confusion(predicted: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """(NUM_CLASSES, NUM_CLASSES) pixel counts [true class, predicted class]; true labels outside the image
    classes (none in generated masks) are left out."""
    if predicted.shape != truth.shape:
        raise ValueError(f"prediction {predicted.shape} and truth {truth.shape} differ in size")
    keep = truth < NUM_CLASSES
    index = truth[keep].astype(np.int64) * NUM_CLASSES + predicted[keep].astype(np.int64)
    return np.bincount(index, minlength=NUM_CLASSES**2).reshape(NUM_CLASSES, NUM_CLASSES)


def class_iou(matrix: np.ndarray) -> np.ndarray:
    """(NUM_CLASSES,) IoU of each class from a confusion matrix; NaN for a class neither present nor predicted."""
    tp = np.diag(matrix).astype(float)
    union = matrix.sum(axis=0) + matrix.sum(axis=1) - tp
    return np.divide(tp, union, out=np.full(tp.shape, np.nan), where=union > 0)


def iou_report(matrix: np.ndarray, images: int) -> dict[str, Any]:
    """Per-class IoU (None for a class neither present nor predicted), their mean and the pixel accuracy."""
    ious = class_iou(matrix)
    per_class = {
        c.name.lower(): (None if np.isnan(ious[i]) else round(float(ious[i]), 4))
        for i, c in enumerate(IMAGE_CLASSES)
    }
    tp = np.diag(matrix).astype(float)
    present = [v for v in per_class.values() if v is not None]
    return {
        "per_class_iou": per_class,
        "mean_iou": round(float(np.mean(present)), 4) if present else None,
        "pixel_accuracy": round(float(tp.sum() / max(matrix.sum(), 1)), 4),
        "images": images,
    }


def site_images(site: Path, *, night: bool = False) -> list[CameraImage]:
    """The camera images of a generated site's data set with the generator's masks (the data set's own, or for
    a mask-free site, `cama synth --no-masks`, those kept in `<site>/ground_truth`), without its night scenes
    unless `night`; ValueError naming the site when it has neither."""
    dataset = truth_dataset(site)
    images = [
        im
        for scene in dataset.scenes
        if night or "night" not in scene.description.lower()
        for ims in scene.images.values()
        for im in ims
        if im.semantic_mask_path is not None
    ]
    if not images:
        raise ValueError(
            f"{site}: no camera image with a semantic mask in {DATASET_DIR}/ or {GROUND_TRUTH_DIR}/"
        )
    return images


def score_images(
    net: SegmentationNet, images: Iterable[CameraImage], device: torch.device, batch_size: int = 8
) -> dict[str, Any]:
    """Per-class IoU of the network's masks, as the segment stage runs it (`SegmentationNet.for_inference`),
    against the images' own semantic masks (at the images' size)."""
    runner = net.for_inference()
    matrix = np.zeros((NUM_CLASSES, NUM_CLASSES), np.int64)
    batch: list[CameraImage] = []
    count = 0

    def flush() -> None:
        nonlocal matrix
        for image, labels in zip(batch, runner.predict([im.load_rgb() for im in batch], device), strict=True):
            matrix += confusion(labels, image.load_semantic())
        batch.clear()

    for image in images:
        batch.append(image)
        count += 1
        if len(batch) == batch_size:
            flush()
    if batch:
        flush()
    return iou_report(matrix, count)


def score_site(checkpoint: Checkpoint, site: Path, device: DeviceName | str = "auto") -> dict[str, Any]:
    """Per-class IoU of a checkpoint on a generated site's day images; SeenSiteError when the checkpoint was
    trained on that site (same seed, layout or location): the check the benchmark relies on."""
    identity = ensure_unseen(checkpoint, site)
    report = score_images(
        checkpoint.net.to(resolve_device(device)), site_images(site), resolve_device(device)
    )
    report["site"] = identity.to_json()
    return report


def score_held_out(net: SegmentationNet, sites: Sequence[Path], device: torch.device) -> dict[str, Any]:
    """Per-class IoU over the day images of held-out sites (training records it in the checkpoint)."""
    images = [im for site in sites for im in site_images(site)]
    report = score_images(net, images, device)
    report["sites"] = [site_identity(site).to_json() for site in sites]
    return report
