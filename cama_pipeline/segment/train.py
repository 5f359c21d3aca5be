"""Training the segmentation network on generated sites (`cama train-segmenter`).

Training pairs are a site's camera images and the generator's semantic masks. Only randomised generator sites
may be used, never a measurement site (`config.MEASUREMENT_SEEDS`, the named presets at their default seed)
and never one sharing a seed, layout or location with a held-out site; the checkpoint records every site it
saw, so that it can refuse to be scored on one (`checkpoint.ensure_unseen`).

Images are held in memory at the network's input width; each step takes random crops after a random rescale
and flip, with extra paint fade (`segment.paint_fade`) and photometric changes (brightness, contrast, gamma,
colour balance, blur, noise) on top of the generator's own variety. Loss: class-weighted cross-entropy (inverse
square-root frequency, capped) plus a soft Dice term for thin classes; AdamW with a one-cycle schedule.
"""

import dataclasses
import json
import logging
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import torch
import torch.nn.functional as F

from cama_pipeline.progress import StageProgress
from cama_pipeline.segment.checkpoint import (
    Checkpoint,
    CheckpointError,
    ensure_unseen,
    load_checkpoint,
    save_checkpoint,
)
from cama_pipeline.segment.config import (
    MEASUREMENT_PRESET_SEED,
    MEASUREMENT_SEEDS,
    NetworkConfig,
    TrainConfig,
)
from cama_pipeline.segment.network import NUM_CLASSES, SegmentationNet
from cama_pipeline.segment.paint_fade import fade_paint
from cama_pipeline.segment.predict import score_held_out, site_images
from cama_pipeline.site_identity import SeenSiteError, SiteIdentity, site_identity

logger = logging.getLogger(__name__)

IGNORE = 255
"""Label of padding pixels (no loss)."""
ONE_CYCLE_DIV_FACTOR = 25.0
"""The one-cycle schedule starts at the peak learning rate over this (torch's default)."""
NAMED_PRESETS = ("tiny", "default", "large")


@dataclass(frozen=True)
class TrainingSet:
    """Images (N arrays (H, W, 3) uint8 RGB) and masks (N arrays (H, W) uint8) at the network's input width."""

    images: list[np.ndarray]
    masks: list[np.ndarray]


def find_sites(paths: Sequence[Path]) -> list[Path]:
    """Generated site folders: each path is one (it holds `manifest.json`) or a folder of them; FileNotFoundError
    naming a path that is neither."""
    sites: list[Path] = []
    for path in map(Path, paths):
        if (path / "manifest.json").is_file():
            sites.append(path)
            continue
        inner = sorted(p for p in path.iterdir() if (p / "manifest.json").is_file()) if path.is_dir() else []
        if not inner:
            raise FileNotFoundError(f"{path}: neither a generated site (manifest.json) nor a folder of them")
        sites.extend(inner)
    return sites


def is_measurement_site(identity: SiteIdentity) -> bool:
    """Whether a site is kept for measurement: a seed of `MEASUREMENT_SEEDS`, or a named preset at its default
    seed (the site of the tests, the demo and the benchmarks)."""
    return identity.seed in MEASUREMENT_SEEDS or (
        identity.preset in NAMED_PRESETS and identity.seed == MEASUREMENT_PRESET_SEED
    )


def check_training_sites(train: Sequence[Path], held_out: Sequence[Path]) -> list[SiteIdentity]:
    """The identities of the training sites; SeenSiteError naming the first site that is a measurement site or
    shares a seed, layout or location with a held-out site."""
    kept = [site_identity(site) for site in held_out]
    identities = []
    for site in train:
        identity = site_identity(site)
        if is_measurement_site(identity):
            raise SeenSiteError(
                f"{site}: a measurement site (preset {identity.preset}, seed {identity.seed}; seeds "
                f"{MEASUREMENT_SEEDS.start}-{MEASUREMENT_SEEDS.stop - 1} and the named presets at seed "
                f"{MEASUREMENT_PRESET_SEED} are kept for measuring); train on other randomised sites"
            )
        for other in kept:
            shared = identity.shares_with(other)
            if shared is not None:
                raise SeenSiteError(f"{site}: has the same {shared} as held-out site {other.path}")
        identities.append(identity)
    return identities


def resize_labels(mask: np.ndarray, size: tuple[int, int], interpolation: int) -> np.ndarray:
    """`mask` (H, W class ids) resized to `size` (width, height) as its image is: each class's indicator is
    resampled with the image's `interpolation` and every pixel takes the class with the largest share. Nearest
    neighbour would move a thin class's edges against the interpolated image by up to half a pixel (README,
    "Training at the images' own scale")."""
    classes = np.unique(mask)
    if classes.size == 1:
        return np.full((size[1], size[0]), classes[0], dtype=mask.dtype)
    shares = np.stack(
        [cv2.resize((mask == c).astype(np.float32), size, interpolation=interpolation) for c in classes]
    )
    return classes[shares.argmax(axis=0)].astype(mask.dtype)


def load_training_set(sites: Sequence[Path], input_width_px: int) -> TrainingSet:
    """Every camera image of the sites with its semantic mask, rescaled to `input_width_px` wide."""
    images, masks = [], []
    for site in sites:
        for image in site_images(site, night=True):
            rgb, mask = image.load_rgb(), image.load_semantic()
            height = max(32, round(rgb.shape[0] * input_width_px / rgb.shape[1]))
            if rgb.shape[1] != input_width_px:
                rgb = cv2.resize(rgb, (input_width_px, height), interpolation=cv2.INTER_AREA)
                mask = resize_labels(mask, (input_width_px, height), cv2.INTER_AREA)
            images.append(rgb)
            masks.append(mask)
    if not images:
        raise ValueError(f"no images with semantic masks in {', '.join(map(str, sites))}")
    return TrainingSet(images, masks)


def class_weights(masks: Sequence[np.ndarray], cap: float) -> torch.Tensor:
    """Inverse square-root class frequencies relative to the median class, clipped to [1 / cap, cap]."""
    counts = np.zeros(NUM_CLASSES)
    for mask in masks[:: max(1, len(masks) // 200)]:
        counts += np.bincount(mask.ravel(), minlength=256)[:NUM_CLASSES]
    freq = counts / counts.sum()
    present = freq > 0
    weights = np.ones(NUM_CLASSES)
    weights[present] = np.sqrt(np.median(freq[present]) / freq[present])
    return torch.tensor(np.clip(weights, 1.0 / cap, cap), dtype=torch.float32)


def augment(
    image: np.ndarray, mask: np.ndarray, config: TrainConfig, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """A random crop (after a random rescale and flip), maybe with its paint faded, with photometric changes;
    float32 RGB in [0, 1]."""
    scale = float(rng.uniform(*config.scale_range))
    height, width = image.shape[:2]
    size = (max(1, round(width * scale)), max(1, round(height * scale)))
    if size != (width, height):
        image = cv2.resize(image, size, interpolation=cv2.INTER_LINEAR)
        mask = resize_labels(mask, size, cv2.INTER_LINEAR)
    ch, cw = config.crop_height_px, config.crop_width_px
    pad_y, pad_x = max(0, ch - size[1]), max(0, cw - size[0])
    if pad_y or pad_x:
        image = cv2.copyMakeBorder(image, 0, pad_y, 0, pad_x, cv2.BORDER_CONSTANT, value=(0, 0, 0))
        mask = cv2.copyMakeBorder(mask, 0, pad_y, 0, pad_x, cv2.BORDER_CONSTANT, value=IGNORE)
    y = int(rng.integers(0, image.shape[0] - ch + 1))
    x = int(rng.integers(0, image.shape[1] - cw + 1))
    image, mask = image[y : y + ch, x : x + cw], mask[y : y + ch, x : x + cw]
    if rng.uniform() < 0.5:
        image, mask = image[:, ::-1], mask[:, ::-1]
    if config.paint_fade_max > 0 and rng.uniform() < 0.5:
        image = fade_paint(image, mask, float(rng.uniform(0.0, config.paint_fade_max)))
    if rng.uniform() < 0.3:
        image = cv2.GaussianBlur(np.ascontiguousarray(image), (0, 0), float(rng.uniform(0.3, 1.2)))
    rgb = image.astype(np.float32) / 255.0
    rgb = rgb ** float(rng.uniform(0.7, 1.4))
    rgb = (rgb - 0.5) * float(rng.uniform(0.7, 1.3)) + 0.5 + float(rng.uniform(-0.15, 0.15))
    rgb = rgb * rng.uniform(0.85, 1.15, size=3).astype(np.float32)
    if rng.uniform() < 0.5:
        rgb = rgb + rng.normal(0.0, float(rng.uniform(0.0, 0.04)), size=rgb.shape).astype(np.float32)
    return np.clip(rgb, 0.0, 1.0), np.ascontiguousarray(mask)


def loss_fn(logits: torch.Tensor, target: torch.Tensor, weights: torch.Tensor) -> torch.Tensor:
    """Weighted cross-entropy plus 0.5 x soft Dice (mean over the classes present in the batch)."""
    ce = F.cross_entropy(logits, target, weight=weights, ignore_index=IGNORE)
    valid = (target != IGNORE).unsqueeze(1)
    probs = logits.softmax(dim=1) * valid
    onehot = F.one_hot(target.clamp(max=NUM_CLASSES - 1), NUM_CLASSES).permute(0, 3, 1, 2) * valid
    inter = (probs * onehot).sum(dim=(0, 2, 3))
    total = probs.sum(dim=(0, 2, 3)) + onehot.sum(dim=(0, 2, 3))
    present = onehot.sum(dim=(0, 2, 3)) > 0
    dice = 1.0 - (2 * inter[present] + 1.0) / (total[present] + 1.0)
    return ce + 0.5 * dice.mean()


def _batches(count: int, batch_size: int, rng: np.random.Generator, steps: int) -> list[np.ndarray]:
    """`steps` batches of image indices, each image once per pass in a random order (passes repeat as needed)."""
    order = np.concatenate([rng.permutation(count) for _ in range(-(-steps * batch_size // count))])
    return [order[i * batch_size : (i + 1) * batch_size] for i in range(steps)]


def _augmented_batches(
    data: TrainingSet, config: TrainConfig, rng: np.random.Generator, steps_per_epoch: int
) -> Iterator[tuple[torch.Tensor, torch.Tensor]]:
    """Endless (images (B, 3, H, W) float, labels (B, H, W) int64) batches of augmented crops, one epoch's
    image order drawn from `rng` at a time (lazily: a consumer that stops draws no more)."""
    while True:
        for batch in _batches(len(data.images), config.batch_size, rng, steps_per_epoch):
            pairs = [augment(data.images[i], data.masks[i], config, rng) for i in batch]
            x = torch.from_numpy(np.stack([p[0] for p in pairs])).permute(0, 3, 1, 2)
            y = torch.from_numpy(np.stack([p[1] for p in pairs]).astype(np.int64))
            yield x, y


class _LoaderStream(torch.utils.data.IterableDataset[tuple[torch.Tensor, torch.Tensor]]):
    """`_augmented_batches` in loader worker processes, each with its own generator seeded by the training seed
    and its worker id (the loader takes their batches in turn, so a run is repeatable for a worker count)."""

    def __init__(self, data: TrainingSet, config: TrainConfig, steps_per_epoch: int):
        self.data, self.config, self.steps_per_epoch = data, config, steps_per_epoch

    def __iter__(self) -> Iterator[tuple[torch.Tensor, torch.Tensor]]:
        worker = torch.utils.data.get_worker_info()
        rng = np.random.default_rng([self.config.seed, 0 if worker is None else worker.id])
        return _augmented_batches(self.data, self.config, rng, self.steps_per_epoch)


def _batch_source(
    data: TrainingSet, config: TrainConfig, steps_per_epoch: int, device: torch.device
) -> Iterator[tuple[torch.Tensor, torch.Tensor]]:
    """The training batches: made in the training loop from one generator (`loader_workers` 0, the crops of
    every checkpoint trained on the CPU), or by `loader_workers` processes, which keep a GPU fed."""
    if config.loader_workers == 0:
        return _augmented_batches(data, config, np.random.default_rng(config.seed), steps_per_epoch)
    loader = torch.utils.data.DataLoader(
        _LoaderStream(data, config, steps_per_epoch),
        batch_size=None,
        num_workers=config.loader_workers,
        pin_memory=device.type == "cuda",
        prefetch_factor=4,
        multiprocessing_context="fork",  # the workers share the images in memory instead of pickling them
    )
    return iter(loader)


@dataclass(frozen=True)
class FitRecord:
    """What a training run did: the mean loss of each pass over the training images (the last one partial when
    a time budget ended it), its steps, and the crops per second it ran at."""

    losses: list[float]
    steps: int
    passes: float
    crops_per_second: float


PROBE_STEPS = 40
"""Steps a time-budgeted run takes at the schedule's starting rate to measure its speed."""
PROBE_UNTIMED_STEPS = 10
"""The first probe steps, left out of the timing: allocator and kernel selection."""


def fit(
    net: SegmentationNet, data: TrainingSet, config: TrainConfig, device: torch.device, *, show_progress: bool
) -> FitRecord:
    """Train `net` in place for `config.epochs` passes, or with `config.time_budget_s` for as many steps as fit in
    that time: the first `PROBE_STEPS` (at the one-cycle schedule's starting rate) measure the speed, and the
    schedule then runs over the steps the rest of the budget holds."""
    started = time.perf_counter()
    weights = class_weights(data.masks, config.max_class_weight).to(device)
    steps_per_epoch = max(1, (config.images_per_epoch or len(data.images)) // config.batch_size)
    batches = _batch_source(data, config, steps_per_epoch, device)
    optimiser = torch.optim.AdamW(net.parameters(), lr=config.learning_rate, weight_decay=config.weight_decay)
    # channels-last: mkldnn convolutions run faster so on the CPU (the stubs lack `to`'s memory_format)
    net.to(memory_format=torch.channels_last).train()  # type: ignore[call-overload]
    epoch_losses: list[float] = []
    losses: list[float] = []

    def step(schedule: torch.optim.lr_scheduler.LRScheduler | None) -> None:
        x, y = next(batches)
        x = x.to(device, non_blocking=True).contiguous(memory_format=torch.channels_last)
        loss = loss_fn(net(x), y.to(device, non_blocking=True), weights)
        optimiser.zero_grad(set_to_none=True)
        loss.backward()
        optimiser.step()
        if schedule is not None:
            schedule.step()
        epoch_losses.append(float(loss.detach()))
        if len(epoch_losses) == steps_per_epoch:
            losses.append(round(float(np.mean(epoch_losses)), 4))
            logger.info("pass %d: loss %.4f", len(losses), losses[-1])
            epoch_losses.clear()

    with StageProgress("train-segmenter", logger=logger, enabled=show_progress) as progress:
        total = config.epochs * steps_per_epoch
        probe, timed_from = 0, started
        bar = progress.add_task("steps", total=PROBE_STEPS if config.time_budget_s else total)
        if config.time_budget_s:
            for group in optimiser.param_groups:
                group["lr"] = config.learning_rate / ONE_CYCLE_DIV_FACTOR
            for probe in range(1, PROBE_STEPS + 1):
                if probe == PROBE_UNTIMED_STEPS + 1:
                    timed_from = time.perf_counter()
                step(None)
                progress.advance(bar)
            seconds_per_step = (time.perf_counter() - timed_from) / (PROBE_STEPS - PROBE_UNTIMED_STEPS)
            left = config.time_budget_s - (time.perf_counter() - started)
            total = PROBE_STEPS + max(1, int(left / seconds_per_step))
            progress.update(bar, total=total)
        schedule = torch.optim.lr_scheduler.OneCycleLR(
            optimiser,
            max_lr=config.learning_rate,
            total_steps=total - probe,
            pct_start=0.15,
            div_factor=ONE_CYCLE_DIV_FACTOR,
        )
        for _ in range(total - probe):
            step(schedule)
            progress.advance(bar)
    if epoch_losses:
        losses.append(round(float(np.mean(epoch_losses)), 4))
    seconds = time.perf_counter() - started
    return FitRecord(
        losses, total, round(total / steps_per_epoch, 2), round(total * config.batch_size / seconds, 1)
    )


def cpu_seconds_per_image(
    net: SegmentationNet,
    width: int = 512,
    height: int = 288,
    repeats: int = 5,
    *,
    flip_average: bool = False,
    as_trained: bool = False,
) -> float:
    """Median seconds one CPU thread takes to segment one `width` x `height` image: the stage's cost (its
    `SegmentationNet.for_inference` copy; with `flip_average` as the stage runs with that setting), or with
    `as_trained` the network as training leaves it (batch norms apart, contiguous weights), the baseline the
    inference copy is measured against."""
    cpu = SegmentationNet(net.config)
    cpu.load_state_dict(net.state_dict())
    cpu.eval()
    runner = cpu if as_trained else cpu.for_inference()
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        image = np.random.default_rng(0).integers(0, 256, (height, width, 3), dtype=np.uint8)
        runner.predict([image], torch.device("cpu"), flip_average=flip_average)
        times = []
        for _ in range(repeats):
            started = time.perf_counter()
            runner.predict([image], torch.device("cpu"), flip_average=flip_average)
            times.append(time.perf_counter() - started)
    finally:
        torch.set_num_threads(threads)
    return round(float(np.median(times)), 4)


def initial_network(
    network: NetworkConfig | None, init: Path | None
) -> tuple[SegmentationNet, Checkpoint | None]:
    """A new network of `network`'s config, or the one of checkpoint `init` to go on training. `init` without a
    full-resolution refinement may go on as `network` with one (same config otherwise): its weights are loaded
    and the refinement starts at zero correction."""
    if init is None:
        return SegmentationNet(network or NetworkConfig()), None
    parent = load_checkpoint(init)
    if network is None or network == parent.net.config:
        return parent.net, parent
    gains_refinement = parent.net.config.full_resolution_width == 0 and network == dataclasses.replace(
        parent.net.config, full_resolution_width=network.full_resolution_width
    )
    if not gains_refinement:
        raise CheckpointError(f"{init}: its network config {parent.net.config} is not the one asked for")
    net = SegmentationNet(network)
    missing, unexpected = net.load_state_dict(parent.net.state_dict(), strict=False)
    if unexpected or any(not key.startswith("refine.") for key in missing):
        raise CheckpointError(
            f"{init}: its weights do not fit {network} (missing {missing}, extra {unexpected})"
        )
    return net, parent


def _place(site: dict[str, Any]) -> str:
    """A recorded training site without its folder: the same site regenerated elsewhere is one place."""
    return json.dumps({k: v for k, v in site.items() if k != "path"}, sort_keys=True)


def _lineage(meta: dict[str, Any], parent: Checkpoint | None) -> dict[str, Any]:
    """`meta` of a run that went on from `parent`: the sites, epochs and seconds of both, and the parent named."""
    if parent is None:
        return meta
    seen = {_place(s) for s in meta["training_sites"]}
    earlier = [s.to_json() for s in parent.training_sites if _place(s.to_json()) not in seen]
    return {
        **meta,
        "training_sites": earlier + meta["training_sites"],
        "epochs_total": int(parent.meta.get("epochs_total", parent.meta.get("epochs", 0))) + meta["epochs"],
        "seconds_total": round(
            float(parent.meta.get("seconds_total", parent.meta.get("seconds", 0.0))) + meta["seconds"], 1
        ),
        "parent": {
            "label": parent.label,
            "path": str(parent.path),
            "weights_sha256": parent.meta["weights_sha256"],
            "train": parent.meta.get("train"),
            "metrics": parent.meta.get("metrics"),
        },
    }


def train(
    config: TrainConfig,
    sites: Sequence[Path],
    out: Path,
    *,
    held_out: Sequence[Path] = (),
    network: NetworkConfig | None = None,
    init: Path | None = None,
    device: torch.device | None = None,
    label: str | None = None,
    show_progress: bool = True,
) -> Path:
    """Train on `sites` (checked by `check_training_sites`; with `init`, going on from that checkpoint, whose
    sites then count as seen too), score on `held_out`, save the checkpoint `out`."""
    started = time.perf_counter()
    device = device or torch.device("cpu")
    torch.set_num_threads(config.threads)
    torch.manual_seed(config.seed)
    train_sites = find_sites(sites)
    held_sites = find_sites(held_out) if held_out else []
    identities = check_training_sites(train_sites, held_sites)
    net, parent = initial_network(network, init)
    for site in held_sites:
        if parent is not None:
            ensure_unseen(parent, site)
    data = load_training_set(train_sites, net.config.input_width_px)
    logger.info("training on %d images of %d sites", len(data.images), len(train_sites))
    record = fit(net.to(device), data, config, device, show_progress=show_progress)
    net.eval()
    metrics: dict[str, Any] = {
        "loss": record.losses,
        "steps": record.steps,
        "crops_per_second": record.crops_per_second,
        "cpu_seconds_per_512x288": cpu_seconds_per_image(net),
    }
    if held_sites:
        metrics["held_out"] = score_held_out(net, held_sites, device)
    meta = {
        "label": label or Path(out).name,
        "train": config.to_json(),
        "epochs": record.passes if config.time_budget_s else config.epochs,
        "images": len(data.images),
        "device": torch.cuda.get_device_name(device) if device.type == "cuda" else "cpu",
        "seconds": round(time.perf_counter() - started, 1),
        "training_sites": [identity.to_json() for identity in identities],
        "held_out_sites": [site_identity(site).to_json() for site in held_sites],
        "metrics": metrics,
    }
    return save_checkpoint(Path(out), net.cpu(), _lineage(meta, parent))
