"""Class calibration of a segmenter checkpoint: one logit offset per class, fitted on sites it never trained on.

The segmenter trains with class-weighted cross-entropy (thin, rare classes weighted up to `max_class_weight`),
and a weight w moves the loss's optimal logit of its class by about log w: the decision boundaries of lane
markings and kerbs sit too far out. On held-out site 9001 the shipped-v2 network's lane-marking pixels were
almost twice the true ones (precision 0.50, recall 0.88; within one pixel of a true marking 0.80). Fitting one
additive offset per class, by coordinate ascent on the mean IoU over the images of a few fresh randomised sites,
undoes that without retraining. The offsets are folded into the classifier's bias (a constant logit shift
survives the bilinear upsampling), so a calibrated checkpoint is an ordinary checkpoint with a new weights
digest (the segment stage reruns with it), and its calibration sites are added to the sites it saw, so it is
never scored on them.
"""

import logging
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from cama_pipeline.data import CameraImage
from cama_pipeline.progress import StageProgress
from cama_pipeline.segment.checkpoint import Checkpoint, ensure_unseen, load_checkpoint, save_checkpoint
from cama_pipeline.segment.network import IMAGE_CLASSES, NUM_CLASSES, SegmentationNet
from cama_pipeline.segment.predict import class_iou, confusion, iou_report, score_held_out, site_images
from cama_pipeline.segment.train import check_training_sites, find_sites
from cama_pipeline.site_identity import site_identity

logger = logging.getLogger(__name__)

CLASS_NAMES = tuple(c.name.lower() for c in IMAGE_CLASSES)
"""The image classes' names, by class id, as `--classes` and the calibration record spell them."""


@dataclass(frozen=True)
class CalibrationConfig:
    """The offsets' search: a grid of `span` either side of the current offset in `step`s, `passes` rounds
    over the classes; logits are kept for every `pixel_stride`-th row and column of each image."""

    span: float = 3.0
    step: float = 0.25
    passes: int = 2
    pixel_stride: int = 4
    classes: tuple[str, ...] = ()
    """Names of the classes whose offsets are fitted (the others keep 0); empty: every class. The road classes
    and background (`background,road,curb,lane_marking,crosswalk`) undo the class weights' pull on the thin ones
    without moving ego and vehicle, whose calibration images (night ones included) differ from the measured ones:
    fitting every class of `refined-cap2` cost site 9001's ego 0.935 -> 0.927."""

    def __post_init__(self) -> None:
        if not (self.span > 0 and 0 < self.step <= self.span):
            raise ValueError(f"CalibrationConfig: need span > 0 and 0 < step <= span, got {self}")
        if self.passes < 1 or self.pixel_stride < 1:
            raise ValueError(f"CalibrationConfig: passes and pixel_stride must be >= 1, got {self}")
        unknown = [name for name in self.classes if name not in CLASS_NAMES]
        if unknown:
            raise ValueError(
                f"CalibrationConfig.classes: unknown class {unknown[0]!r}; choose from {list(CLASS_NAMES)}"
            )

    def fitted_classes(self) -> list[int]:
        """Indices of the classes whose offsets are fitted."""
        return (
            [CLASS_NAMES.index(name) for name in self.classes] if self.classes else list(range(NUM_CLASSES))
        )


@dataclass(frozen=True)
class PixelLogits:
    """Logits (N, NUM_CLASSES) of sampled pixels and their true class ids (N,)."""

    logits: torch.Tensor
    truth: torch.Tensor


def collect_logits(
    net: SegmentationNet,
    images: Sequence[CameraImage],
    device: torch.device,
    pixel_stride: int,
    *,
    show_progress: bool = True,
) -> PixelLogits:
    """The network's logits at every `pixel_stride`-th pixel of each image (at the image's own size, as the
    segment stage predicts) with the image's true class; pixels of no image class are left out."""
    logits, truth = [], []
    with StageProgress("calibrate-segmenter", logger=logger, enabled=show_progress) as progress:
        bar = progress.add_task("logits of images", total=len(images))
        for image in images:
            rgb = image.load_rgb()
            batch = torch.from_numpy(rgb).to(device).permute(2, 0, 1)[None].float() / 255.0
            with torch.inference_mode():
                out = net.logits_at_size(batch, rgb.shape[:2])[0, :, ::pixel_stride, ::pixel_stride]
            labels = torch.from_numpy(image.load_semantic()[::pixel_stride, ::pixel_stride].astype(np.int64))
            keep = labels.reshape(-1) < NUM_CLASSES
            logits.append(out.reshape(NUM_CLASSES, -1).T.cpu()[keep])
            truth.append(labels.reshape(-1)[keep])
            progress.advance(bar)
    if not logits:
        raise ValueError("segmenter calibration: no image with a semantic mask to calibrate on")
    return PixelLogits(torch.cat(logits), torch.cat(truth))


def confusion_of(pixels: PixelLogits, offsets: np.ndarray) -> np.ndarray:
    """(NUM_CLASSES, NUM_CLASSES) counts [true, predicted] with `offsets` added to the logits."""
    predicted = (pixels.logits + torch.as_tensor(offsets, dtype=pixels.logits.dtype)).max(dim=1).indices
    return confusion(predicted.numpy(), pixels.truth.numpy())


def mean_iou(matrix: np.ndarray) -> float:
    """Mean IoU over the classes present or predicted (unrounded: the offsets' search compares close values)."""
    ious = class_iou(matrix)
    return float(np.nanmean(ious)) if not np.isnan(ious).all() else 0.0


def fit_logit_offsets(
    pixels: PixelLogits, config: CalibrationConfig, *, show_progress: bool = True
) -> np.ndarray:
    """Per-class offsets maximising the mean IoU: for each fitted class in turn, the best offset on a grid
    around its current one, the others held; `config.passes` rounds. Starts at zero, so never worse than none.
    With every class fitted the offsets are centred (only differences matter to the argmax); with some, the
    others stay exactly 0."""
    offsets = np.zeros(NUM_CLASSES)
    best = mean_iou(confusion_of(pixels, offsets))
    grid = np.arange(-config.span, config.span + config.step / 2, config.step)
    fitted = config.fitted_classes()
    with StageProgress("calibrate-segmenter", logger=logger, enabled=show_progress) as progress:
        bar = progress.add_task("class offsets", total=config.passes * len(fitted))
        for _ in range(config.passes):
            for cls in fitted:
                start = offsets[cls]
                for value in start + grid:
                    trial = offsets.copy()
                    trial[cls] = value
                    score = mean_iou(confusion_of(pixels, trial))
                    if score > best + 1e-6:
                        best, offsets = score, trial
                progress.advance(bar)
    return offsets if config.classes else offsets - offsets.mean()


def calibrated_network(net: SegmentationNet, offsets: np.ndarray) -> SegmentationNet:
    """A copy of `net` whose classifier bias carries `offsets`."""
    calibrated = SegmentationNet(net.config)
    calibrated.load_state_dict(net.state_dict())
    bias = calibrated.head.bias
    if bias is None:
        raise ValueError("segmenter calibration: the network's classifier has no bias to carry the offsets")
    with torch.no_grad():
        bias += torch.as_tensor(offsets, dtype=bias.dtype)
    return calibrated.eval()


def calibrate(
    sites: Sequence[Path],
    out: Path,
    *,
    checkpoint: Path | None = None,
    held_out: Sequence[Path] = (),
    config: CalibrationConfig = CalibrationConfig(),
    device: torch.device | None = None,
    label: str | None = None,
    show_progress: bool = True,
) -> Path:
    """Calibrate `checkpoint` (default: the shipped one) on the images of `sites` (randomised sites it never
    saw, not measurement sites, sharing nothing with `held_out`) and save the result as checkpoint `out`,
    recording the offsets, the IoU on the calibration images before and after, and (re-scored) on `held_out`."""
    started = time.perf_counter()
    device = device or torch.device("cpu")
    calibration_sites = find_sites(sites)
    held_sites = find_sites(held_out) if held_out else []
    identities = check_training_sites(calibration_sites, held_sites)
    parent = load_checkpoint(checkpoint)
    for site in [*calibration_sites, *held_sites]:  # SeenSiteError: its logits would be over-confident
        ensure_unseen(parent, site)
    images = [im for site in calibration_sites for im in site_images(site, night=True)]
    pixels = collect_logits(
        parent.net.to(device), images, device, config.pixel_stride, show_progress=show_progress
    )
    offsets = fit_logit_offsets(pixels, config, show_progress=show_progress)
    net = calibrated_network(parent.net.cpu(), offsets)
    metrics: dict[str, Any] = {k: v for k, v in parent.meta.get("metrics", {}).items() if k != "held_out"}
    if held_sites:  # the parent's held-out figures are not this network's
        metrics["held_out"] = score_held_out(net.to(device), held_sites, device)
    meta = {
        **{k: v for k, v in parent.meta.items() if k not in ("weights_sha256", "created_at", "code_version")},
        "label": label or Path(out).name,
        "training_sites": [s.to_json() for s in parent.training_sites] + [i.to_json() for i in identities],
        "held_out_sites": [site_identity(site).to_json() for site in held_sites],
        "metrics": metrics,
        "calibration": calibration_record(parent, pixels, offsets, identities, len(images), config, started),
    }
    return save_checkpoint(Path(out), net.cpu(), meta)


def calibration_record(
    parent: Checkpoint,
    pixels: PixelLogits,
    offsets: np.ndarray,
    sites: Sequence[Any],
    images: int,
    config: CalibrationConfig,
    started: float,
) -> dict[str, Any]:
    """What a calibrated checkpoint records of its calibration."""
    return {
        "parent": {
            "label": parent.label,
            "path": str(parent.path),
            "weights_sha256": parent.meta["weights_sha256"],
        },
        "offsets": {name: round(float(v), 3) for name, v in zip(CLASS_NAMES, offsets, strict=True)},
        "sites": [s.to_json() for s in sites],
        "images": images,
        "pixel_stride": config.pixel_stride,
        "classes_fitted": [CLASS_NAMES[i] for i in config.fitted_classes()],
        "before": iou_report(confusion_of(pixels, np.zeros(NUM_CLASSES)), images),
        "after": iou_report(confusion_of(pixels, offsets), images),
        "seconds": round(time.perf_counter() - started, 1),
    }
