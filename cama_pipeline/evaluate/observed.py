"""True vectors cut to the part of a site that cameras observed: what a reconstructed map can be judged on.

A reconstruction only covers the road its clips drove along; the generator's truth goes on beyond. Scoring
proposals, or an annotator who would need imagery to draw, on road nobody saw measures the route, not the map.
Open polylines keep their observed stretches; a closed ring (crosswalk) is kept whole when most of it was seen.
"""

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from annotations.geometry import densify
from cama_pipeline.semantics import Semantic


@dataclass(frozen=True)
class ObservedMask:
    """Which raster cells were observed (semantic != 255), with the raster's georeference (DESIGN.md rasters)."""

    observed: np.ndarray
    origin_xy: tuple[float, float]
    resolution_m: float

    @classmethod
    def from_semantic(
        cls, semantic: np.ndarray, origin_xy: Sequence[float], resolution_m: float, close_m: float = 0.5
    ) -> "ObservedMask":
        """The observed cells of a semantic raster, small unobserved holes (label noise) closed."""
        seen = (np.asarray(semantic) != int(Semantic.UNOBSERVED)).astype(np.uint8)
        size = 2 * max(1, round(close_m / resolution_m)) + 1
        seen = cv2.morphologyEx(seen, cv2.MORPH_CLOSE, np.ones((size, size), np.uint8))
        return cls(seen > 0, (float(origin_xy[0]), float(origin_xy[1])), float(resolution_m))

    def contains(self, xy: np.ndarray) -> np.ndarray:
        """Per global (x, y) point: inside the raster and on an observed cell."""
        col = np.rint((xy[:, 0] - self.origin_xy[0]) / self.resolution_m).astype(np.int64)
        row = np.rint((self.origin_xy[1] - xy[:, 1]) / self.resolution_m).astype(np.int64)
        height, width = self.observed.shape
        inside = (row >= 0) & (row < height) & (col >= 0) & (col < width)
        hit = np.zeros(len(xy), dtype=bool)
        hit[inside] = self.observed[row[inside], col[inside]]
        return hit


def _length(points: np.ndarray) -> float:
    return float(np.linalg.norm(np.diff(points, axis=0), axis=1).sum())


def observed_parts(
    points: np.ndarray,
    closed: bool,
    mask: ObservedMask,
    *,
    step_m: float = 0.25,
    min_length_m: float = 2.0,
    min_ring_share: float = 0.5,
) -> list[np.ndarray]:
    """The observed pieces of one 2D polyline (global metres): stretches at least `min_length_m` long, or the
    whole ring when at least `min_ring_share` of it lies on observed cells."""
    dense = densify(np.asarray(points, dtype=np.float64)[:, :2], step_m)
    seen = mask.contains(dense)
    if closed:
        return [np.asarray(points, dtype=np.float64)[:, :2]] if seen.mean() >= min_ring_share else []
    edges = np.diff(np.concatenate([[0], seen.astype(np.int8), [0]]))
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    pieces = [dense[s:e] for s, e in zip(starts, ends, strict=True)]
    return [p for p in pieces if len(p) >= 2 and _length(p) >= min_length_m]
