"""Whole-site inference of the learned model: overlapping sliding windows, merged into site vectors.

Windows of the model's patch size step by `patch - overlap` over the site's model-resolution grid (the last
row/column of windows is flush with the far edge; a site smaller than one patch is zero-padded). Each window's
predictions above `min_score` become global vectors (score: the best class probability), clipped to the
window's core and merged (`models.vma.merge`). An anchored model first runs the rule-based proposer on the
site; each window's anchors are those candidates clipped to the window, and only anchored slots are output
(its free slots, measured on validation sites, proposed nothing right: precision 1 in 6,800).
"""

import logging
from dataclasses import dataclass

import numpy as np
import torch

from cama_pipeline.progress import StageProgress
from models.vma.anchors import Anchors, patch_anchors, stack_anchors
from models.vma.config import ModelConfig
from models.vma.merge import MergeConfig, clip_to_core, core_bounds, merge_windows
from models.vma.model import VmaNet
from models.vma.patches import MIN_TARGET_LENGTH_PX, SiteGrid, site_grid
from models.vma.rasters import SiteRasters
from models.vma.rule_based import RuleConfig, propose_rule_based
from models.vma.vectors import CLASSES, Vector

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class InferenceConfig:
    """Sliding-window inference settings."""

    overlap_px: int = 32
    """Overlap of neighbouring windows in model pixels (8 m at 0.25 m/px)."""
    min_score: float = 0.05
    """Predictions scoring lower are dropped before merging."""
    batch_size: int = 8
    merge: MergeConfig = MergeConfig()
    rule: RuleConfig = RuleConfig()
    """How an anchored model's candidates are proposed (the rule-based proposer's settings)."""
    anchored_output: str = "rescored"
    """Anchored models: 'rescored' keeps each rule-based candidate's full-resolution geometry with the model's
    score (length-weighted mean over windows of its class probability), 'refined' outputs the model's points."""

    def __post_init__(self) -> None:
        if self.anchored_output not in ("rescored", "refined"):
            raise ValueError(
                f"InferenceConfig.anchored_output must be 'rescored' or 'refined', got {self.anchored_output!r}"
            )
        if self.overlap_px < 0 or not 0.0 <= self.min_score < 1.0 or self.batch_size < 1:
            raise ValueError(
                "InferenceConfig: overlap_px >= 0, 0 <= min_score < 1 and batch_size >= 1 required"
            )


def window_origins(length: int, patch: int, overlap: int) -> list[int]:
    """Start offsets of windows covering [0, length) with at least `overlap` shared between neighbours."""
    if overlap >= patch:
        raise ValueError(f"InferenceConfig.overlap_px {overlap} must be smaller than the patch ({patch} px)")
    if length <= patch:
        return [0]
    count = int(np.ceil((length - patch) / (patch - overlap))) + 1
    return [int(round(v)) for v in np.linspace(0, length - patch, count)]


def predict_site(
    model: VmaNet, rasters: SiteRasters, config: InferenceConfig | None = None, *, show_progress: bool = True
) -> list[Vector]:
    """Site vectors (global metres, with confidence) predicted by `model` over the whole site."""
    config = config or InferenceConfig()
    grid = site_grid(rasters, model.config)
    windows = _windows(grid, model.config, config.overlap_px)
    device = next(model.parameters()).device
    rule = propose_rule_based(rasters, config.rule) if model.config.anchored else []
    candidates = (
        [Vector(v.cls, grid.pixel_from_global(v.points), v.score) for v in rule]
        if model.config.anchored
        else None
    )
    weighted = np.zeros((len(rule), 2))  # per candidate: sum of length x own-class probability, sum of length
    pieces: list[Vector] = []
    with StageProgress("vma", logger=logger, enabled=show_progress) as progress, torch.no_grad():
        bar = progress.add_task("propose windows", total=len(windows))
        for start in range(0, len(windows), config.batch_size):
            chunk = windows[start : start + config.batch_size]
            images = torch.as_tensor(
                np.stack([_crop(grid, model.config, w[0], w[1]) for w in chunk]), device=device
            )
            windows_anchors = (
                [_window_anchors(candidates, model.config, col, row) for col, row, _ in chunk]
                if candidates is not None
                else []
            )
            anchors = stack_anchors(windows_anchors, device)
            logits, points = model(images, anchors)
            probabilities = torch.sigmoid(logits)
            if anchors is not None:  # free slots of an anchored model only add false positives
                probabilities = probabilities * anchors[1][..., -1:]
            scores = probabilities.cpu().numpy()
            final = points[-1].cpu().numpy()
            if anchors is not None:
                _accumulate(weighted, anchors[1].cpu().numpy(), scores, windows_anchors)
            for (col, row, core), s, p in zip(chunk, scores, final, strict=True):
                window_vectors = _window_vectors(grid, model.config, col, row, s, p, config.min_score)
                pieces += clip_to_core(window_vectors, core, config.merge.min_length_m)
            progress.advance(bar, len(chunk))
    if model.config.anchored and config.anchored_output == "rescored":
        score = weighted[:, 0] / np.maximum(weighted[:, 1], 1e-9)
        vectors = [
            Vector(v.cls, v.points, float(s))
            for v, s in zip(rule, score, strict=True)
            if s >= config.min_score
        ]
    else:
        vectors = merge_windows(pieces, config.merge)
    logger.info(
        "learned proposer: %d vectors from %d windows on %s", len(vectors), len(windows), rasters.name
    )
    return vectors


def _windows(
    grid: SiteGrid, model_config: ModelConfig, overlap: int
) -> list[tuple[int, int, tuple[float, float, float, float]]]:
    """(col, row, core bounds in global metres) of every window."""
    _, height, width = grid.image.shape
    size = model_config.patch_px
    cols = window_origins(width, size, overlap)
    rows = window_origins(height, size, overlap)
    centre_x = [grid.global_from_pixel(np.array([[c + (size - 1) / 2, 0]]))[0, 0] for c in cols]
    centre_y = [grid.global_from_pixel(np.array([[0, r + (size - 1) / 2]]))[0, 1] for r in rows]
    out = []
    for j, row in enumerate(rows):
        # y decreases with rows: core bounds over ascending y, mapped back to this row's index
        ys = centre_y[::-1]
        y_lo, y_hi = core_bounds(ys, len(rows) - 1 - j)
        for i, col in enumerate(cols):
            x_lo, x_hi = core_bounds(centre_x, i)
            out.append((col, row, (x_lo, x_hi, y_lo, y_hi)))
    return out


def _accumulate(
    weighted: np.ndarray, features: np.ndarray, scores: np.ndarray, windows_anchors: list[Anchors]
) -> None:
    """Add each anchored slot's own-class probability, weighted by its piece length, to its candidate."""
    for window_features, window_scores, anchors in zip(features, scores, windows_anchors, strict=True):
        for slot in np.flatnonzero(anchors.sources >= 0):
            own_class = int(np.argmax(window_features[slot, : len(CLASSES)]))
            weighted[anchors.sources[slot]] += anchors.lengths[slot] * np.array(
                [window_scores[slot, own_class], 1.0]
            )


def _window_anchors(candidates: list[Vector], model_config: ModelConfig, col: int, row: int) -> Anchors:
    """Anchors of the window at (col, row) from site candidates in grid pixels."""
    offset = np.array([col - 0.5, row - 0.5])
    return patch_anchors(
        [Vector(v.cls, v.points - offset, v.score) for v in candidates], model_config, MIN_TARGET_LENGTH_PX
    )


def _crop(grid: SiteGrid, model_config: ModelConfig, col: int, row: int) -> np.ndarray:
    """The window's input, zero-padded where it passes the site edge."""
    size = model_config.patch_px
    out = np.zeros((grid.image.shape[0], size, size), np.float32)
    part = grid.image[:, row : row + size, col : col + size]
    out[:, : part.shape[1], : part.shape[2]] = part
    return out


def _window_vectors(
    grid: SiteGrid,
    model_config: ModelConfig,
    col: int,
    row: int,
    scores: np.ndarray,
    points: np.ndarray,
    min_score: float,
) -> list[Vector]:
    """A window's predictions above `min_score` as global vectors (rings closed exactly)."""
    out = []
    for query_scores, query_points in zip(scores, points, strict=True):
        k = int(np.argmax(query_scores))
        if query_scores[k] < min_score:
            continue
        pixels = query_points * model_config.patch_px - 0.5 + np.array([col, row])
        xy = grid.global_from_pixel(pixels)
        if CLASSES[k] == "ped_crossing":
            xy = np.vstack([xy[:-1], xy[:1]])
        out.append(Vector(CLASSES[k], xy, float(query_scores[k])))
    return out


def predict_patch(model: VmaNet, image: np.ndarray, min_score: float = 0.05) -> list[Vector]:
    """Predictions of one (C, S, S) patch in patch pixels (col, row), for tests and diagnostics."""
    grid = SiteGrid(image, (0.0, 0.0), 1.0)
    with torch.no_grad():
        logits, points = model(torch.as_tensor(image[None], device=next(model.parameters()).device))
    scores = torch.sigmoid(logits)[0].cpu().numpy()
    return [
        Vector(v.cls, np.column_stack([v.points[:, 0], -v.points[:, 1]]), v.score)
        for v in _window_vectors(grid, model.config, 0, 0, scores, points[-1][0].cpu().numpy(), min_score)
    ]
