"""Training the learned VMA model from site patches and procedural patches, with a progress bar.

`train` is the `cama train` stage: it builds a fresh model (or continues from a checkpoint of the same
config), trains it for `TrainConfig.steps` batches mixing procedural patches with patches of the training
sites, and saves the result as a new version of a checkpoint registry with the data it saw. An anchored
model also trains on damaged copies of each site (`models.vma.degrade`, seeds disjoint from the benchmark's)
with the rule-based candidates of each copy as anchors, so it learns to correct the candidates that damaged
rasters produce.
"""

import logging
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import numpy as np
import torch

from cama_pipeline.progress import StageProgress
from models.vma.anchors import stack_anchors
from models.vma.checkpoint import load_checkpoint, promote, refuse_seen_validation, save_version, seen_records
from models.vma.config import ModelConfig, TrainConfig, config_dict
from models.vma.degrade import DegradeConfig, degrade_rasters
from models.vma.evaluate import evaluate_proposer
from models.vma.infer import predict_site
from models.vma.loop import THRESHOLD_KEY
from models.vma.matching import batch_targets, match_and_loss
from models.vma.model import VmaNet
from models.vma.patches import Sample, SiteGrid, degrade, procedural_sample, random_site_sample, site_grid
from models.vma.rasters import SiteRasters, load_site_rasters, vector_map_of
from models.vma.rule_based import propose_rule_based
from models.vma.vectors import Vector, read_vectors

logger = logging.getLogger(__name__)

Sampler = Callable[[np.random.Generator], Sample]


@dataclass(frozen=True, eq=False)
class TrainingSite:
    """A site ready for patch sampling: its model-resolution grid and vectors (and anchored: candidates)."""

    name: str
    grid: SiteGrid
    vectors: list[Vector]
    candidates: list[Vector] | None = None
    """Rule-based candidates on these rasters (global metres), for anchored models."""


DAMAGE_SEED_BASE = 7_000_000
"""Damage seeds of training copies start here, far from the benchmark's (sum of a site name's bytes)."""


def load_training_sites(path: Path, config: ModelConfig, damaged_copies: int = 0) -> list[TrainingSite]:
    """A site folder's rasters and ground truth, plus `damaged_copies` damaged versions for anchored models
    (each with its rule-based candidates); errors name the file."""
    rasters = load_site_rasters(path)
    vectors = read_vectors(vector_map_of(path))
    if not config.anchored:
        return [TrainingSite(str(path), site_grid(rasters, config), vectors)]
    versions = [rasters] + [
        degrade_rasters(rasters, DegradeConfig(seed=DAMAGE_SEED_BASE + 1000 * k + sum(str(path).encode())))
        for k in range(damaged_copies)
    ]
    return [_anchored_site(str(path), r, vectors, config) for r in versions]


def _anchored_site(
    name: str, rasters: SiteRasters, vectors: list[Vector], config: ModelConfig
) -> TrainingSite:
    return TrainingSite(name, site_grid(rasters, config), vectors, propose_rule_based(rasters))


def device_for() -> torch.device:
    """CUDA when present, else CPU."""
    return torch.device("cuda" if torch.cuda.is_available() else "cpu")


def mixed_sampler(sites: Sequence[TrainingSite], config: ModelConfig, procedural_share: float) -> Sampler:
    """Draws a procedural patch with probability `procedural_share` (always when no site), else a site patch."""

    def draw(rng: np.random.Generator) -> Sample:
        if not sites or rng.random() < procedural_share:
            sample = procedural_sample(config, rng)
        else:
            site = sites[int(rng.integers(len(sites)))]
            sample = random_site_sample(site.grid, site.vectors, config, rng, site.candidates)
        if sample.anchors is not None:  # anchored samples are damaged before the candidates are found
            return sample
        return degrade(sample, rng) if rng.random() < 0.5 else sample

    return draw


def learning_rate_at(progress: float, peak: float, warmup: float = 0.05) -> float:
    """Linear warm-up to `peak`, then cosine decay to 5% of it, by training progress in [0, 1]."""
    if progress < warmup:
        return peak * max(progress, 0.01) / warmup
    t = min(1.0, (progress - warmup) / (1.0 - warmup))
    return peak * (0.05 + 0.95 * 0.5 * (1.0 + np.cos(np.pi * t)))


class Schedule(Protocol):
    """The optimisation settings every training config carries (`TrainConfig`, the element-mask network's)."""

    @property
    def steps(self) -> int: ...
    @property
    def learning_rate(self) -> float: ...
    @property
    def weight_decay(self) -> float: ...
    @property
    def seed(self) -> int: ...
    @property
    def threads(self) -> int: ...
    @property
    def max_seconds(self) -> float: ...


BatchLoss = Callable[[np.random.Generator, torch.device], tuple[torch.Tensor, Any]]
"""One batch drawn with the generator, its loss on the device, and loss parts to log."""


def optimise(
    model: torch.nn.Module,
    batch_loss: BatchLoss,
    config: Schedule,
    *,
    label: str = "training",
    clip_norm: float | None = None,
    show_progress: bool = True,
) -> list[float]:
    """Train `model` in place with AdamW for `config.steps` batches or `config.max_seconds`, whichever ends first.

    The learning-rate schedule follows progress (the larger of the step and time fractions), so a run cut
    by its time budget still ends with a decayed rate. Every 50 steps a `step i/n loss x` record goes to this
    module's logger (the backend's retrain job reports them). Returns the loss of each step."""
    device = device_for()
    if device.type == "cpu":
        torch.set_num_threads(config.threads)
    torch.manual_seed(config.seed)
    rng = np.random.default_rng(config.seed)
    model.to(device).train()
    optimiser = torch.optim.AdamW(
        model.parameters(), lr=config.learning_rate, weight_decay=config.weight_decay
    )
    started = time.perf_counter()
    losses: list[float] = []
    with StageProgress(label, logger=logger, enabled=show_progress) as progress:
        bar = progress.add_task(total=config.steps)
        for step in range(config.steps):
            loss, parts = batch_loss(rng, device)
            optimiser.zero_grad()
            loss.backward()
            if clip_norm is not None:
                torch.nn.utils.clip_grad_norm_(model.parameters(), clip_norm)
            done = max((step + 1) / config.steps, (time.perf_counter() - started) / config.max_seconds)
            for group in optimiser.param_groups:
                group["lr"] = learning_rate_at(done, config.learning_rate)
            optimiser.step()
            losses.append(float(loss.detach()))
            progress.update(bar, advance=1, description=f"loss {np.mean(losses[-20:]):.3f}")
            if step % 50 == 0 or done >= 1.0:
                logger.info("step %d/%d loss %.4f %s", step + 1, config.steps, np.mean(losses[-50:]), parts)
            if done >= 1.0:
                break
    model.eval()
    return losses


def fit(model: VmaNet, sampler: Sampler, config: TrainConfig, *, show_progress: bool = True) -> list[float]:
    """Train the MapTR-style `model` in place on `sampler`'s patches (`optimise`; gradients clipped at 1)."""

    def batch_loss(rng: np.random.Generator, device: torch.device) -> tuple[torch.Tensor, Any]:
        batch = [sampler(rng) for _ in range(config.batch_size)]
        images = torch.as_tensor(np.stack([s.image for s in batch]), device=device)
        labels, points = batch_targets([s.labels for s in batch], [s.points for s in batch], device)
        logits, layer_points = model(images, stack_anchors([s.anchors for s in batch], device))
        return match_and_loss(logits, layer_points, labels, points, config.class_weight, config.point_weight)

    return optimise(model, batch_loss, config, clip_norm=1.0, show_progress=show_progress)


def train(
    model_config: ModelConfig,
    train_config: TrainConfig,
    sites: Sequence[Path],
    registry: Path,
    *,
    init: Path | None = None,
    damaged_copies: int = 3,
    promote_result: bool = True,
    validation_sites: Sequence[Path] = (),
    show_progress: bool = True,
) -> Path:
    """Train a model on `sites` (+ procedural patches), save it as a new promoted version of `registry`.

    An anchored model also sees `damaged_copies` damaged versions of each site. With `promote_result` False
    the version is only saved (to be promoted by the evaluation gate, `models.vma.retrain.gate_checkpoint`).
    With `validation_sites` its validation Chamfer-AP and calibrated pre-accept threshold are recorded."""
    started = time.perf_counter()
    parent = load_checkpoint(init, model_config) if init is not None else None
    seen = seen_records(sites, parent)
    refuse_seen_validation(seen, validation_sites, "the model being trained")
    training_sites = [t for p in sites for t in load_training_sites(Path(p), model_config, damaged_copies)]
    model = parent.model if parent is not None else VmaNet(model_config)
    losses = fit(
        model,
        mixed_sampler(training_sites, model_config, train_config.procedural_share),
        train_config,
        show_progress=show_progress,
    )
    model.cpu()
    metrics: dict[str, Any] = {
        "final_loss": float(np.mean(losses[-50:])),
        "steps_done": len(losses),
        "seconds": round(time.perf_counter() - started, 1),
    }
    if validation_sites:
        metrics["validation"] = evaluate_proposer(
            lambda rasters: predict_site(model, rasters, show_progress=False), validation_sites
        )
    meta = {
        "parent": str(init) if init is not None else None,
        "train_config": config_dict(train_config),
        "metrics": metrics,
        THRESHOLD_KEY: metrics.get("validation", {}).get(THRESHOLD_KEY),
        "data": {
            "sites": [str(p) for p in sites],
            **seen,
            "procedural_share": train_config.procedural_share,
            "damaged_copies": damaged_copies if model_config.anchored else 0,
            "samples_seen": len(losses) * train_config.batch_size,
            "seed": train_config.seed,
        },
    }
    folder = save_version(registry, model, meta)
    if promote_result:
        promote(registry, folder.name)
    return folder
