"""Training the element-mask network on site rasters with their vectors, with a progress bar.

A training site is its rasters, clean and in `damaged_copies` damaged versions (`models.vma.degrade` at random
strengths, plus smeared and broken kerb labels and the unseen strip a kerb's face hides, as surface
reconstructions give them), with its vectors drawn
as target masks. Crops are cut at random road cells and rotations, and in some a random half-plane is made
unobserved (input and target emptied: what no camera saw cannot be drawn). Loss: binary cross-entropy plus soft
Dice per class (the masks are thin and rare). Generator ground truth and annotators' corrections are both
just vectors, so the same `fit` trains a model from scratch and fine-tunes it on corrections.
"""

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import torch
from torch.nn import functional

from annotations.geometry import resample_spacing
from cama_pipeline.semantics import ROAD_SURFACE_IDS, Semantic
from models.vma.checkpoint import promote, refuse_seen_validation, save_version, seen_records
from models.vma.config import config_dict
from models.vma.degrade import DegradeConfig, degrade_rasters
from models.vma.element_masks.checkpoint import KIND, MaskCheckpoint
from models.vma.element_masks.config import MaskModelConfig, MaskTrainConfig
from models.vma.element_masks.net import ElementMaskNet
from models.vma.element_masks.targets import element_masks
from models.vma.patches import site_grid
from models.vma.rasters import NUM_SEMANTIC, SiteRasters, load_site_rasters
from models.vma.train import DAMAGE_SEED_BASE, optimise
from models.vma.validation import (
    ValidationEntry,
    ValidationSite,
    as_validation_site,
    reconstructions,
    true_vectors,
    truth_folder,
)
from models.vma.vectors import Vector


@dataclass(frozen=True, eq=False)
class MaskTrainingSite:
    """One site ready for cropping: input grids (clean first, then damaged) and the target masks."""

    name: str
    images: list[np.ndarray]
    """(C, H, W) float32 network inputs of the same ground."""
    targets: np.ndarray
    """(K, H, W) float32 element masks."""
    road: np.ndarray
    """(2, N) rows and cols of the grid cells crops are centred on (road cells, or points of corrected elements)."""


def damaged_versions(rasters: SiteRasters, copies: int, seed: int) -> list[SiteRasters]:
    """`copies` reconstruction-like versions of a site's rasters, each at its own random damage strength."""
    rng = np.random.default_rng(seed)
    out = []
    for k in range(copies):
        config = DegradeConfig(
            marking_dropout=float(rng.uniform(0.0, 0.35)),
            speckle=float(rng.uniform(0.0, 0.01)),
            edge_jitter_px=int(rng.integers(0, 3)),
            colour_noise=float(rng.uniform(0.0, 0.06)),
            seed=seed + 1 + k,
        )
        damaged = degrade_rasters(rasters, config)
        smeared = replace(damaged, semantic=smeared_kerbs(damaged.semantic, rasters.resolution_m, rng))
        out.append(hidden_kerb_strip(smeared, rng) if rng.random() < 0.6 else smeared)
    return out


def hidden_kerb_strip(rasters: SiteRasters, rng: np.random.Generator) -> SiteRasters:
    """The strip beside the road that a kerb's face hides from cameras driving on the road: the kerb label and the
    off-road ground within a random 0.1-0.8 m of it made unobserved (no class, no colour), along random stretches,
    so the road meets unseen ground directly, as on the surface stage's rasters. The boundary is still there."""
    semantic = rasters.semantic
    curb = (semantic == int(Semantic.CURB)).astype(np.uint8)
    if not curb.any():
        return rasters
    strip = _kerb_band(curb, 0.8, rasters.resolution_m, rng)
    hidden = strip & _random_stretches(semantic.shape, 80, 0.7, rng) & ~np.isin(semantic, ROAD_SURFACE_IDS)
    out_semantic, photometric = semantic.copy(), rasters.photometric.copy()
    out_semantic[hidden] = int(Semantic.UNOBSERVED)
    photometric[hidden] = 0
    return replace(rasters, semantic=out_semantic, photometric=photometric)


def smeared_kerbs(semantic: np.ndarray, resolution_m: float, rng: np.random.Generator) -> np.ndarray:
    """Kerb labels as a surface reconstruction leaves them: spread up to a metre over the off-road side in
    places, and missing (read as off-road ground) along random stretches."""
    out = semantic.copy()
    curb = (semantic == int(Semantic.CURB)).astype(np.uint8)
    if not curb.any():
        return out
    grown = _kerb_band(curb, 1.0, resolution_m, rng)
    patches = _random_stretches(semantic.shape, 40, 0.5, rng)
    out[grown & patches & (semantic == int(Semantic.BACKGROUND))] = int(Semantic.CURB)
    gaps = _random_stretches(semantic.shape, 30, 0.2, rng)
    out[gaps & (out == int(Semantic.CURB))] = int(Semantic.BACKGROUND)
    return out


def _kerb_band(curb: np.ndarray, max_m: float, resolution_m: float, rng: np.random.Generator) -> np.ndarray:
    """The kerb cells grown by a random 0.1 m to `max_m` (bool)."""
    radius = max(1, round(float(rng.uniform(0.1, max_m)) / resolution_m))
    return cv2.dilate(curb, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1,) * 2)) > 0


def _random_stretches(
    shape: tuple[int, ...], cell_px: int, share: float, rng: np.random.Generator
) -> np.ndarray:
    """A (H, W) bool mask of random square blocks of `cell_px` cells, each on with probability `share`."""
    coarse = rng.random((max(1, shape[0] // cell_px), max(1, shape[1] // cell_px))) < share
    return cv2.resize(coarse.astype(np.uint8), (shape[1], shape[0]), interpolation=cv2.INTER_NEAREST) > 0


def training_site(
    name: str,
    rasters: SiteRasters,
    vectors: Sequence[Vector],
    config: MaskModelConfig,
    damaged_copies: int,
    seed: int,
    *,
    centres_on: Sequence[Vector] | None = None,
    context_m: float = 0.0,
) -> MaskTrainingSite:
    """A site's inputs (clean + damaged) and target masks on the network's grid; crops are centred on its road
    cells, or, when `centres_on` (corrected and rejected elements) is given, on their points and on as many road
    cells within `context_m` of them (the reviewed region's road between the elements, where nothing is to be
    drawn)."""
    grid = site_grid(rasters, config)
    images = [grid.image] + [
        site_grid(r, config).image for r in damaged_versions(rasters, damaged_copies, seed)
    ]
    if centres_on is None:
        rows, cols = np.nonzero(grid.image[1:NUM_SEMANTIC].sum(axis=0) > 0.5)
    else:
        points = [resample_spacing(v.points, 2.0) for v in centres_on]
        colrow = grid.pixel_from_global(np.vstack(points)) if points else np.zeros((0, 2))
        size, edge = np.array([grid.shape[1], grid.shape[0]]), 0.5 + 1e-6  # a cell's edge, to float precision
        inside = ((colrow >= -edge) & (colrow <= size - 1 + edge)).all(axis=1)
        cols, rows = np.clip(np.rint(colrow[inside]), 0, size - 1).astype(int).T
        if context_m > 0 and rows.size:
            points_mask = np.zeros(grid.shape, np.uint8)
            points_mask[rows, cols] = 1
            radius = max(1, round(context_m / grid.resolution_m))
            near = (
                cv2.dilate(points_mask, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1,) * 2))
                > 0
            )
            road_rows, road_cols = np.nonzero(near & (grid.image[1:NUM_SEMANTIC].sum(axis=0) > 0.5))
            pick = np.random.default_rng(seed).permutation(road_rows.size)[: rows.size]
            rows, cols = np.concatenate([rows, road_rows[pick]]), np.concatenate([cols, road_cols[pick]])
    if rows.size == 0:
        raise ValueError(f"{name}: no road cell or element on the rasters to train on")
    return MaskTrainingSite(name, images, element_masks(vectors, grid, config), np.stack([rows, cols]))


def load_mask_training_site(
    entry: ValidationEntry, config: MaskModelConfig, damaged_copies: int
) -> MaskTrainingSite:
    """A generated site's rasters and ground-truth vectors as a training site (errors name the file): a path
    trains on the site's own rasters and `damaged_copies` damaged versions, a reconstruction
    (`models.vma.validation.reconstruction_of`) on the surface stage's rasters of its data set as they are (the
    damage only imitates them) against the truth its cameras observed, which is what the product proposes on."""
    site = as_validation_site(entry)
    rasters = load_site_rasters(site.rasters)
    vectors = true_vectors(site, rasters)
    name = str(site if site.reconstructed else site.site)
    copies = 0 if site.reconstructed else damaged_copies
    return training_site(name, rasters, vectors, config, copies, DAMAGE_SEED_BASE + sum(name.encode()))


def jitter_appearance(image: np.ndarray, rng: np.random.Generator) -> None:
    """Give a (C, H, W) network input another photometric appearance in place, on its observed cells only:
    contrast about the crop's mean colour 0.4-1.3 (faded paint, light asphalt), gamma 0.7-1.4, exposure gain
    0.5-2.2 (log-uniform), a tint of +-8 % per channel, then clipped to [0, 1] as a camera saturates. The
    ranges cover the randomised generator's (asphalt lightness 0.18-0.5, exposure 0.7-1.35, paint fade up to
    0.45) with room for real logs."""
    rgb = image[NUM_SEMANTIC:]
    observed = image[:NUM_SEMANTIC].sum(axis=0) > 0.5
    if not observed.any():
        return
    values = rgb[:, observed]
    mean = values.mean(axis=1, keepdims=True)
    values = mean + float(rng.uniform(0.4, 1.3)) * (values - mean)
    values = np.clip(values, 0.0, 1.0) ** float(rng.uniform(0.7, 1.4))
    gain = float(np.exp(rng.uniform(np.log(0.5), np.log(2.2))))
    values = values * gain * rng.uniform(0.92, 1.08, (3, 1))
    rgb[:, observed] = np.clip(values, 0.0, 1.0)


def random_crop(
    site: MaskTrainingSite,
    crop_px: int,
    unobserved_share: float,
    rng: np.random.Generator,
    appearance_share: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """A rotated crop (input, target) centred near a random road cell of a random version of the site; with
    probability `appearance_share` in another appearance (`jitter_appearance`)."""
    image = site.images[int(rng.integers(len(site.images)))]
    k = int(rng.integers(site.road.shape[1]))
    centre = site.road[::-1, k].astype(np.float64) + rng.uniform(-crop_px / 4, crop_px / 4, 2)
    angle = float(rng.uniform(0, 2 * np.pi))
    c, s = np.cos(angle), np.sin(angle)
    half = (crop_px - 1) / 2
    rotation = np.array([[c, -s], [s, c]])
    site_from_crop = np.hstack([rotation, (centre - rotation @ np.array([half, half]))[:, None]])
    flags = cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP

    def warp(channels: np.ndarray) -> np.ndarray:
        return np.stack(
            [cv2.warpAffine(ch, site_from_crop, (crop_px, crop_px), flags=flags) for ch in channels]
        )

    crop, target = warp(image), warp(site.targets)
    if rng.random() < appearance_share:
        jitter_appearance(crop, rng)
    if rng.random() < unobserved_share:
        normal = rng.normal(size=2)
        cols, rows = np.meshgrid(np.arange(crop_px) - half, np.arange(crop_px) - half)
        hidden = cols * normal[0] + rows * normal[1] > rng.uniform(-0.3, 0.5) * crop_px * np.linalg.norm(
            normal
        )
        crop[:, hidden] = 0.0
        target[:, hidden] = 0.0
    return crop, target


def mask_loss(logits: torch.Tensor, targets: torch.Tensor) -> torch.Tensor:
    """Binary cross-entropy plus soft Dice, averaged over classes."""
    bce = functional.binary_cross_entropy_with_logits(logits, targets)
    probabilities = torch.sigmoid(logits)
    overlap = (probabilities * targets).sum(dim=(0, 2, 3))
    total = probabilities.sum(dim=(0, 2, 3)) + targets.sum(dim=(0, 2, 3))
    dice = 1.0 - (2.0 * overlap + 1.0) / (total + 1.0)
    return bce + dice.mean()


def fit_masks(
    model: ElementMaskNet,
    sites: Sequence[MaskTrainingSite],
    config: MaskTrainConfig,
    *,
    site_weights: Sequence[float] | None = None,
    show_progress: bool = True,
) -> list[float]:
    """Train `model` in place for `config.steps` batches or `config.max_seconds`; returns each step's loss.
    Each crop comes from a site drawn with `site_weights` (relative; default: every site alike, drawn as before
    weights existed, so earlier seeded runs repeat exactly)."""
    if not sites:
        raise ValueError("element-mask training: no training site")
    draw_site = site_drawer(len(sites), site_weights)

    def batch_loss(rng: np.random.Generator, device: torch.device) -> tuple[torch.Tensor, str]:
        crops = [
            random_crop(
                sites[draw_site(rng)],
                config.crop_px,
                config.unobserved_share,
                rng,
                config.appearance_share,
            )
            for _ in range(config.batch_size)
        ]
        images = torch.as_tensor(np.stack([c for c, _ in crops]), device=device)
        targets = torch.as_tensor(np.stack([t for _, t in crops]), device=device)
        return mask_loss(model(images), targets), ""

    return optimise(model, batch_loss, config, label="element-mask training", show_progress=show_progress)


def share_weights(sites: Sequence[ValidationEntry], reconstruction_share: float) -> list[float]:
    """Relative site weights that draw `reconstruction_share` of the crops from the reconstructions among `sites`
    and the rest from the others, each group's sites alike. Why: with every site alike, adding reconstructions
    shrinks the share of generator rasters the network keeps seeing (ValueError unless the share is in (0, 1) and
    both kinds are there)."""
    reconstructed = [
        isinstance(s, ValidationSite) and s.reconstructed for s in sites
    ]  # a path: its own rasters
    count = sum(reconstructed)
    if not 0.0 < reconstruction_share < 1.0 or count in (0, len(sites)):
        raise ValueError(
            f"element-mask training: reconstruction_share must lie in (0, 1) with reconstructions and other sites "
            f"both given, got {reconstruction_share} with {count} of {len(sites)} sites reconstructed"
        )
    return [
        reconstruction_share / count if r else (1.0 - reconstruction_share) / (len(sites) - count)
        for r in reconstructed
    ]


def site_drawer(count: int, weights: Sequence[float] | None) -> Callable[[np.random.Generator], int]:
    """A function drawing a site index: uniformly, or by relative `weights` (ValueError when they are not
    `count` non-negative numbers with a positive sum)."""
    if weights is None:
        return lambda rng: int(rng.integers(count))
    relative = np.asarray(weights, dtype=np.float64)
    if relative.shape != (count,) or not np.all(relative >= 0) or not relative.sum() > 0:
        raise ValueError(
            f"element-mask training: site_weights must be {count} non-negative numbers, not all 0"
        )
    probabilities = relative / relative.sum()
    return lambda rng: int(rng.choice(count, p=probabilities))


def train_masks(
    model_config: MaskModelConfig,
    train_config: MaskTrainConfig,
    sites: Sequence[ValidationEntry],
    registry: Path,
    *,
    parent: MaskCheckpoint | None = None,
    validation_sites: Sequence[ValidationEntry] = (),
    reconstruction_share: float | None = None,
    promote_result: bool = True,
    show_progress: bool = True,
) -> Path:
    """Train (or, from `parent`, continue) the network on generated `sites` (their own rasters, or their
    reconstructions); save a new version of `registry` that records every site it and its parents saw (refusing
    `validation_sites` among them). `reconstruction_share`: the share of crops drawn from the reconstructions
    (`share_weights`; None: every site alike)."""
    started = time.perf_counter()
    weights = None if reconstruction_share is None else share_weights(sites, reconstruction_share)
    seen = seen_records([truth_folder(s) for s in sites], parent)
    refuse_seen_validation(seen, validation_sites, "the element-mask model being trained")
    training = [load_mask_training_site(s, model_config, train_config.damaged_copies) for s in sites]
    model = parent.model if parent is not None else ElementMaskNet(model_config)
    losses = fit_masks(model, training, train_config, site_weights=weights, show_progress=show_progress)
    model.cpu()
    metrics: dict[str, Any] = {
        "final_loss": float(np.mean(losses[-100:])),
        "steps_done": len(losses),
        "seconds": round(time.perf_counter() - started, 1),
    }
    meta = {
        "kind": KIND,
        "parent": str(parent.path) if parent is not None else None,
        "train_config": config_dict(train_config),
        "metrics": metrics,
        "data": {
            "sites": [str(truth_folder(s)) for s in sites],
            "reconstructions": [str(s.rasters) for s in reconstructions(sites)],
            **seen,
            "damaged_copies": train_config.damaged_copies,
            "samples_seen": len(losses) * train_config.batch_size,
            "reconstruction_share": reconstruction_share,
            "seed": train_config.seed,
        },
    }
    folder = save_version(registry, model, meta)
    if promote_result:
        promote(registry, folder.name)
    return folder
