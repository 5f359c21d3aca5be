"""Kerb steps: which off-road cells stand at curb height, decided by photo-consistency at two heights.

The elevation MLP is smooth by design (a few encoding octaves), so it cannot hold the 10-15 cm step where the road
meets a raised kerb and sidewalk. The observation pass samples every visible cell in every image twice: at the MLP's
height and `curb_height_m` above it. A cell really at one of the two heights is seen in the same place by every
camera at that height, so its colour agrees across the views; at the other height each camera sees another patch of
ground (the parallax grows with the camera's distance), so the colours disagree. The cell is raised when its views
agree better at curb height: the log ratio of the two weighted colour variances, averaged over the neighbouring
off-road cells (a sidewalk or a kerb is a region, not a cell) and above `threshold`. Optionally (`kerb_band_m`)
road-labelled cells next to a raised region that agree better at curb height too are the kerb's foot: raised and
labelled curb. Painted cells (lane marking, crosswalk) are never the foot: paint lies on the road, and a crossing
runs up to the kerb, so a foot across it would cut the crossing's end (default site, SfM poses: crosswalk IoU 0.893
with painted cells in the foot, 0.898 without, as without a foot). A kerb's edge is a line, so the foot is not
decided cell by cell (that leaves patches and a ragged road edge): along the kerb, the foot's width is the one of
0.1, 0.2, ... `kerb_band_m` whose cells, summed over `foot_smoothing_m` of the kerb's length, agree best at curb
height; the cells within that width of the raised region are the foot, so the road's edge moves as a whole.

The kerb line (`kerb_line`, on by default) finds the kerb's road-labelled cells from the two class votes instead. Seen
from a camera on the road at a distance L from the kerb (across it) and a height h, a cell on the kerb top read at
road level is seen on the kerb's face or the road in front of it up to L c / (h - c) beyond the kerb line (c the
kerb's height), so the road-level vote calls the kerb road out to there; a road cell read at curb height is seen on
the kerb's face from L c / h before the line, so the curb-height vote calls the road off-road from there. The two
smears are nearly equal and opposite, so where the road classes take half of the two votes together (their
road-level share plus their curb-height share is 1) is the kerb line, whatever the views' distances. Road-labelled
cells on the far side of it (the sum under 1, averaged over `kerb_line_smoothing_m`) stand on the step and take the
classes seen at curb height, as the other raised cells do; painted cells never. Without it, on the default site
with SfM poses, about half the true curb cells are labelled road (`bench/kerb_profile.py`). At 256x144 the masks'
blur lowers the road-level vote's road share just before the kerb as well, so there the line also takes a road row.

Otherwise road classes (road, lane marking, crosswalk) are never raised: the road is what the MLP fits, and only
the kerb line (on by default) and the foot (off) raise road-labelled cells. The BEV `elevation` layer
stays that road surface (the vectors are lifted onto it, as CAMA's road elevation map); the step goes to its own
raster (`outputs.write_kerb_step`), to the mesh, and decides which height a cell's colour and classes are taken
from.
"""

from dataclasses import dataclass

import numpy as np
import torch
from scipy import ndimage

from cama_pipeline.semantics import BEV_CLASSES, ROAD_SURFACE_IDS, Semantic
from cama_pipeline.surface.grid import SurfaceGrid

VARIANCE_FLOOR = 1e-4
"""Added to both colour variances before their ratio (RGB in [0, 1]): flat cells get a ratio near 1."""


@dataclass(frozen=True)
class KerbStepConfig:
    """Parameters of the kerb step (`surface.kerb_step` in a run configuration)."""

    enabled: bool = True
    """Raise the off-road cells whose views agree better at curb height (see the module docstring)."""
    threshold: float = 0.2
    """Smoothed log ratio (road-level variance over curb-height variance) above which a cell is raised."""
    smoothing_m: float = 0.3
    """Gaussian sigma of the averaging over neighbouring off-road cells."""
    min_area_m2: float = 0.5
    """Raised regions smaller than this are dropped (a kerb or sidewalk is larger)."""
    kerb_band_m: float = 0.0
    """The widest kerb foot: road-labelled cells up to this far from a raised region are raised too (and
    labelled curb) where the views along the kerb agree better at curb height (the module docstring); the
    road-level vote labels the lower part of a kerb road. 0: no foot."""
    foot_smoothing_m: float = 1.0
    """Gaussian sigma (along the kerb) of the sums that choose the foot's width."""
    kerb_line: bool = True
    """Raise the road-labelled cells beyond the kerb line that the two class votes place (module docstring; curb
    IoU 0.40 -> 0.66 and 0.36 -> 0.45 with SfM poses on two default-size sites, README "The kerb line")."""
    kerb_line_smoothing_m: float = 0.1
    """Gaussian sigma of the averaging of the road classes' two-vote share over neighbouring cells."""

    def __post_init__(self) -> None:
        for name in (
            "smoothing_m",
            "min_area_m2",
            "kerb_band_m",
            "foot_smoothing_m",
            "kerb_line_smoothing_m",
        ):
            if not getattr(self, name) >= 0:
                raise ValueError(f"KerbStepConfig.{name} must be >= 0, got {getattr(self, name)}")


class ColourMoments:
    """Per-vertex weighted sums of `channels` values (RGB by default) and of their squares, for the weighted
    mean and variance across views (`refine` keeps colour and class frequencies per height hypothesis in one)."""

    def __init__(self, vertices: int, device: torch.device, channels: int = 3):
        self.weight = torch.zeros(vertices, device=device)
        self.sum = torch.zeros((vertices, channels), device=device)
        self.square = torch.zeros((vertices, channels), device=device)

    def add(self, ids: torch.Tensor, values: torch.Tensor, weight: torch.Tensor) -> None:
        """Add (N,) vertex ids' (N, channels) samples with (N,) weights."""
        self.weight.index_add_(0, ids, weight)
        self.sum.index_add_(0, ids, values * weight[:, None])
        self.square.index_add_(0, ids, values.square() * weight[:, None])

    def mean(self) -> torch.Tensor:
        """(V, channels) weighted mean (0 where unseen)."""
        return self.sum / self.weight.clamp(min=1e-12)[:, None]

    def channel_variance(self) -> torch.Tensor:
        """(V, channels) weighted variance of each channel (0 where unseen)."""
        mean = self.mean()
        second = self.square / self.weight.clamp(min=1e-12)[:, None]
        return (second - mean.square()).clamp(min=0)

    def variance(self) -> torch.Tensor:
        """(V,) weighted variance summed over the channels (0 where unseen)."""
        return self.channel_variance().sum(dim=1)


def _local_mean(grid: SurfaceGrid, values: np.ndarray, where: np.ndarray, sigma_m: float) -> np.ndarray:
    """(rows, cols) Gaussian-weighted mean of the (V,) `values` over the vertices in `where` near each cell."""
    rows, cols = grid.vertex_cells()
    total = np.zeros((grid.rows, grid.cols))
    support = np.zeros((grid.rows, grid.cols))
    total[rows[where], cols[where]] = values[where]
    support[rows[where], cols[where]] = 1.0
    sigma = sigma_m / grid.resolution_m
    if sigma > 0:
        total = ndimage.gaussian_filter(total, sigma, mode="constant")
        support = ndimage.gaussian_filter(support, sigma, mode="constant")
    return np.divide(total, support, out=np.zeros_like(total), where=support > 1e-6)


def _drop_small(raised: np.ndarray, min_area_m2: float, resolution_m: float) -> np.ndarray:
    """`raised` without its 8-connected regions smaller than `min_area_m2`."""
    labelled, count = ndimage.label(raised, structure=np.ones((3, 3)))
    if not count:
        return raised
    areas = ndimage.sum(raised, labelled, index=np.arange(1, count + 1)) * resolution_m**2
    return raised & ~np.isin(labelled, np.flatnonzero(areas < min_area_m2) + 1)


def curb_height_agreement(road_level: ColourMoments, curb_level: ColourMoments) -> np.ndarray:
    """(V,) how much better each vertex's views agree in colour at curb height than at road level: the log ratio
    of the two weighted colour variances (each floored by `VARIANCE_FLOOR`), positive where curb height fits."""
    ratio = (road_level.variance() + VARIANCE_FLOOR) / (curb_level.variance() + VARIANCE_FLOOR)
    return torch.log(ratio).cpu().numpy()


def raised_vertices(
    grid: SurfaceGrid,
    road_level: ColourMoments,
    curb_level: ColourMoments,
    off_road: np.ndarray,
    painted: np.ndarray,
    config: KerbStepConfig,
) -> tuple[np.ndarray, np.ndarray]:
    """(V,) bool twice: the vertices standing at curb height, and those of them labelled with a road class
    (`off_road` (V,) False), which are kerb cells the road-level vote smeared (see the module docstring); the
    `painted` (V,) vertices (lane marking, crosswalk) are never among the latter."""
    both = ((road_level.weight > 0) & (curb_level.weight > 0)).cpu().numpy()
    score = curb_height_agreement(road_level, curb_level)
    rows, cols = grid.vertex_cells()
    candidates = both & off_road
    mean = _local_mean(grid, score, candidates, config.smoothing_m)
    raised = np.zeros((grid.rows, grid.cols), bool)
    raised[rows[candidates], cols[candidates]] = mean[rows[candidates], cols[candidates]] > config.threshold
    raised = _drop_small(raised, config.min_area_m2, grid.resolution_m)[rows, cols]
    if config.kerb_band_m <= 0:
        return raised, np.zeros_like(raised)
    foot = _kerb_foot(grid, score, both & ~off_road & ~painted, raised, config)
    return raised | foot, foot


def beyond_kerb_line(
    grid: SurfaceGrid,
    road_level: np.ndarray,
    curb_height: np.ndarray,
    seen: np.ndarray,
    candidates: np.ndarray,
    config: KerbStepConfig,
) -> np.ndarray:
    """(V,) the `candidates` (road-labelled, unpainted vertices) beyond the kerb line: where the road classes'
    road-level plus curb-height shares ((V, 5) class shares each, 0 unseen), averaged over the `seen` vertices
    within `kerb_line_smoothing_m`, fall under 1 (see the module docstring)."""
    road_columns = [BEV_CLASSES.index(c) for c in ROAD_SURFACE_IDS]
    both_votes = road_level[:, road_columns].sum(axis=1) + curb_height[:, road_columns].sum(axis=1)
    rows, cols = grid.vertex_cells()
    mean = _local_mean(grid, both_votes, seen, config.kerb_line_smoothing_m)[rows, cols]
    return candidates & seen & (mean < 1.0)


def _kerb_foot(
    grid: SurfaceGrid, score: np.ndarray, road: np.ndarray, raised: np.ndarray, config: KerbStepConfig
) -> np.ndarray:
    """(V,) the `road` vertices within the foot's width of a `raised` one: at each cell, the width (a whole
    number of cells up to `kerb_band_m`) whose band cells' scores above `threshold`, summed with a Gaussian
    of `foot_smoothing_m`, are largest; no foot where every width sums to <= 0."""
    rows, cols = grid.vertex_cells()
    raised_cells = np.zeros((grid.rows, grid.cols), bool)
    raised_cells[rows[raised], cols[raised]] = True
    distance = ndimage.distance_transform_edt(~raised_cells, sampling=grid.resolution_m)[rows, cols]
    gain = score - config.threshold
    best_sum, best_width = np.zeros(len(rows)), np.zeros(len(rows))
    steps = int(np.floor(config.kerb_band_m / grid.resolution_m + 1e-6))
    for width in np.arange(1, steps + 1) * grid.resolution_m:
        band = road & (distance <= width + 1e-6)
        summed = np.zeros((grid.rows, grid.cols))
        summed[rows[band], cols[band]] = gain[band]
        summed = ndimage.gaussian_filter(summed, config.foot_smoothing_m / grid.resolution_m, mode="constant")
        at_vertices = summed[rows, cols]
        better = at_vertices > best_sum
        best_sum[better], best_width[better] = at_vertices[better], width
    return road & (distance <= best_width + 1e-6) & (best_width > 0)


def step_summary(semantic: np.ndarray, kerb_step: np.ndarray, height_m: float) -> dict[str, float | int]:
    """The report's account of the step rasters: its height, the raised cells and their share of the observed
    off-road cells (curb and background)."""
    raised = np.nan_to_num(kerb_step) > 0
    off_road = np.isin(semantic, [int(Semantic.BACKGROUND), int(Semantic.CURB)])
    return {
        "height_m": height_m,
        "cells_raised": int(raised.sum()),
        "off_road_share_raised": float(raised[off_road].mean()) if off_road.any() else 0.0,
    }
