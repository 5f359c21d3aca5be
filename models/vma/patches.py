"""Training samples: square patches (model input + target vectors in normalised patch coordinates).

Targets are the patch's vectors resampled to the model's fixed point count, with x = col / S and
y = row / S in [0, 1]; rings keep first == last. Site patches are cut at random centres and rotations from a
site's model-resolution input, with the site's vectors mapped through the same transform. Samples for an
anchored model also carry the rule-based candidates of the patch as anchors (`models.vma.anchors`): a site's
candidates (computed once on its rasters) mapped like its vectors, or for procedural patches the rule-based
proposer run on the drawn patch itself.
"""

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

import cv2
import numpy as np

from annotations.geometry import resample_fixed
from cama_pipeline.bev import RasterGeoreference
from models.vma.anchors import Anchors, patch_anchors
from models.vma.config import ModelConfig
from models.vma.procedural import procedural_patch
from models.vma.rasters import NUM_SEMANTIC, SiteRasters, model_input
from models.vma.rule_based import propose_rule_based
from models.vma.vectors import CLASSES, Vector, clip_vectors

MIN_TARGET_LENGTH_PX = 4.0
"""Target pieces shorter than this (1 m at 0.25 m/px) are not asked for."""


@dataclass(frozen=True, eq=False)
class Sample:
    """One training patch."""

    image: np.ndarray
    """(C, S, S) float32 model input."""
    labels: np.ndarray
    """(G,) int64 class indices into CLASSES."""
    points: np.ndarray
    """(G, P, 2) float32 normalised patch coordinates."""
    anchors: Anchors | None = None
    """Rule-based candidates as anchor queries (anchored models only)."""


@dataclass(frozen=True, eq=False)
class SiteGrid:
    """A site's model-resolution input with the pixel <-> global mapping of that grid."""

    image: np.ndarray
    """(C, H, W) float32."""
    origin_xy: tuple[float, float]
    """Global metres of grid pixel (0, 0)'s centre."""
    resolution_m: float

    def pixel_from_global(self, xy: np.ndarray) -> np.ndarray:
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        return (
            np.column_stack([(xy[:, 0] - self.origin_xy[0]), (self.origin_xy[1] - xy[:, 1])])
            / self.resolution_m
        )

    def global_from_pixel(self, colrow: np.ndarray) -> np.ndarray:
        colrow = np.asarray(colrow, dtype=np.float64).reshape(-1, 2) * self.resolution_m
        return np.column_stack([self.origin_xy[0] + colrow[:, 0], self.origin_xy[1] - colrow[:, 1]])

    @property
    def shape(self) -> tuple[int, int]:
        """(height, width) in grid pixels."""
        return (int(self.image.shape[1]), int(self.image.shape[2]))


class GridResolution(Protocol):
    """What `site_grid` reads of a model config (the MapTR-style model's or the element-mask network's)."""

    @property
    def resolution_m(self) -> float: ...


def site_grid(rasters: SiteRasters, config: GridResolution) -> SiteGrid:
    """The model input of a whole site; grid pixel i's centre is native pixel (i + 0.5) / scale - 0.5."""
    shift = 0.5 * config.resolution_m - 0.5 * rasters.resolution_m
    origin = (rasters.origin_xy[0] + shift, rasters.origin_xy[1] - shift)
    return SiteGrid(model_input(rasters, config.resolution_m), origin, config.resolution_m)


def targets(vectors: Sequence[Vector], size_px: int, num_points: int) -> tuple[np.ndarray, np.ndarray]:
    """Labels and (G, P, 2) normalised points of vectors given in patch pixels (col, row)."""
    pieces = clip_vectors(vectors, (0.0, float(size_px), 0.0, float(size_px)), MIN_TARGET_LENGTH_PX)
    labels = np.array([CLASSES.index(v.cls) for v in pieces], np.int64)
    points = np.zeros((len(pieces), num_points, 2), np.float32)
    for k, v in enumerate(pieces):
        points[k] = resample_fixed(v.points, num_points) / size_px
    return labels, points


def procedural_sample(config: ModelConfig, rng: np.random.Generator) -> Sample:
    """A procedurally drawn patch as a training sample."""
    semantic, photometric, vectors = procedural_patch(config.patch_px, config.resolution_m, rng)
    image = _input_from(semantic, photometric)
    labels, points = targets(vectors, config.patch_px, config.num_points)
    anchors = None
    if config.anchored:
        h, w = semantic.shape
        geo = RasterGeoreference(origin_xy=(0.0, 0.0), resolution=config.resolution_m, width=w, height=h)
        drawn = SiteRasters(semantic, photometric, geo, "procedural")
        candidates = [
            Vector(v.cls, drawn.pixel_from_global(v.points) + 0.5, v.score) for v in propose_rule_based(drawn)
        ]
        anchors = patch_anchors(candidates, config, MIN_TARGET_LENGTH_PX)
    return Sample(image, labels, points, anchors)


def _input_from(semantic: np.ndarray, photometric: np.ndarray) -> np.ndarray:
    """(C, S, S) input of a patch drawn at model resolution."""
    one_hot = np.stack([(semantic == c).astype(np.float32) for c in range(NUM_SEMANTIC)])
    return np.concatenate([one_hot, photometric.astype(np.float32).transpose(2, 0, 1) / 255.0])


def site_sample(
    grid: SiteGrid,
    vectors: Sequence[Vector],
    config: ModelConfig,
    centre_px: np.ndarray,
    angle_rad: float,
    candidates: Sequence[Vector] | None = None,
) -> Sample:
    """The patch centred at grid pixel `centre_px`, rotated by `angle_rad`, with its vectors (and the site's
    rule-based `candidates` as anchors when given)."""
    size = config.patch_px
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    rotation = np.array([[c, -s], [s, c]])
    # site pixel = rotation @ (patch pixel - half) + centre
    half = np.array([(size - 1) / 2, (size - 1) / 2])
    site_from_patch = np.hstack([rotation, (centre_px - rotation @ half)[:, None]])
    channels = [
        cv2.warpAffine(ch, site_from_patch, (size, size), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP)
        for ch in grid.image
    ]

    def to_patch(v: Vector) -> Vector:
        site_px = grid.pixel_from_global(v.points)
        # pixel centres at +0.5 in patch coordinates
        return Vector(v.cls, (site_px - site_from_patch[:, 2]) @ rotation + 0.5, v.score)

    labels, points = targets([to_patch(v) for v in vectors], size, config.num_points)
    anchors = None
    if candidates is not None:
        anchors = patch_anchors([to_patch(v) for v in candidates], config, MIN_TARGET_LENGTH_PX)
    return Sample(np.stack(channels).astype(np.float32), labels, points, anchors)


def random_site_sample(
    grid: SiteGrid,
    vectors: Sequence[Vector],
    config: ModelConfig,
    rng: np.random.Generator,
    candidates: Sequence[Vector] | None = None,
) -> Sample:
    """A site patch at a random road cell (any rotation), with anchors when `candidates` are given."""
    road = grid.image[1:NUM_SEMANTIC].sum(axis=0) > 0.5
    rows, cols = np.nonzero(road[::4, ::4])
    k = int(rng.integers(len(rows)))
    centre = np.array([cols[k] * 4, rows[k] * 4], np.float64) + rng.uniform(-2, 2, 2)
    return site_sample(grid, vectors, config, centre, float(rng.uniform(0, 2 * np.pi)), candidates)


def degrade(sample: Sample, rng: np.random.Generator) -> Sample:
    """Reconstruction-like noise on the semantic channels: speckle and a few markings erased to road."""
    image = sample.image.copy()
    _, h, w = image.shape
    speckle = rng.random((h, w)) < rng.uniform(0.0, 0.01)
    image[:NUM_SEMANTIC, speckle] = 0.0
    image[rng.integers(NUM_SEMANTIC, size=int(speckle.sum())), *np.nonzero(speckle)] = 1.0
    for _ in range(int(rng.integers(0, 4))):
        r, c = rng.integers(0, h - 8), rng.integers(0, w - 8)
        size = int(rng.integers(4, 12))
        block = (slice(None), slice(r, r + size), slice(c, c + size))
        marking = image[3][block[1:]] > 0
        image[1][block[1:]][marking] = 1.0
        image[3][block[1:]][marking] = 0.0
    return Sample(image, sample.labels, sample.points, sample.anchors)
