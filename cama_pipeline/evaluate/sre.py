"""Semantic reprojection error (CAMAv2 Algorithm 2) for one image: projected map instances against
skeletonised image instances, matched with the Hungarian algorithm.

Cost of a (projected, image) pair: mean distance from the image instance's skeleton pixels to the projected
curve. Pairs over the gate are never matched. Thresholds are given in pixels of the reference width (960 px,
the scale the CAMA code reports at) and converted to the image's own scale.
"""

import logging
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import linear_sum_assignment

from annotations.schema import ELEMENT_CLASSES
from cama_pipeline.evaluate.projection import ProjectedPiece, ProjectionConfig
from cama_pipeline.evaluate.skeleton import skeletonize
from cama_pipeline.evaluate.sre_cama_config import SRE_PROTOCOLS, CamaProtocolConfig, SreProtocol
from cama_pipeline.semantics import INSTANCE_ID_BASE, Semantic

logger = logging.getLogger(__name__)

_CHUNK = 2_000_000
"""Largest (pixels x segments) block of distances computed at once."""


@dataclass(frozen=True)
class SreConfig:
    """Settings of the SRE / precision / recall evaluation."""

    protocol: SreProtocol = "strict"
    """`strict` (the project's own rules, the fields below) or `cama` (CAMA's published metric code, the rules
    and constants in `cama`; only lane markings, so `class_pairs` must be the default)."""
    class_pairs: tuple[tuple[str, int], ...] = (("divider", int(Semantic.LANE_MARKING)),)
    """(map class, instance-mask semantic id) pairs matched against each other; add
    ("boundary", Semantic.CURB) to evaluate road boundaries against curb instances."""
    gate_px: float = 30.0
    """Largest matching cost, in pixels at `reference_width_px`."""
    reference_width_px: int = 960
    """Image width the reported `*_ref_px` figures and the pixel thresholds refer to (CAMA: 960x540)."""
    min_skeleton_px: int = 10
    """Image instances with fewer skeleton pixels (at the reference width) are ignored."""
    min_projected_length_px: float = 20.0
    """Projected instances shorter than this in the image (at the reference width) are ignored."""
    ignore_beyond_range: bool = True
    """Leave out skeleton pixels whose nearest projected point is an end cut by the range crop: markings
    farther than the crop range are not map error."""
    projection: ProjectionConfig = field(default_factory=ProjectionConfig)
    """How map polylines are cropped and projected (strict protocol)."""
    cama: CamaProtocolConfig = field(default_factory=CamaProtocolConfig)
    """Constants of the `cama` protocol."""

    def __post_init__(self) -> None:
        if self.protocol not in SRE_PROTOCOLS:
            raise ValueError(
                f"SreConfig.protocol: unknown {self.protocol!r}, expected one of {SRE_PROTOCOLS}"
            )
        lane_markings = (("divider", int(Semantic.LANE_MARKING)),)
        if self.protocol == "cama" and tuple((m, int(c)) for m, c in self.class_pairs) != lane_markings:
            raise ValueError(
                "SreConfig: the cama protocol scores lane markings only (class_pairs = dividers)"
            )
        if not self.class_pairs:
            raise ValueError("SreConfig.class_pairs must name at least one (map class, mask class) pair")
        for map_class, mask_class in self.class_pairs:
            if map_class not in ELEMENT_CLASSES:
                raise ValueError(
                    f"SreConfig.class_pairs: unknown map class {map_class!r}, expected {ELEMENT_CLASSES}"
                )
            if int(mask_class) not in {int(s) for s in Semantic} or int(mask_class) in (0, 255):
                raise ValueError(f"SreConfig.class_pairs: {mask_class} is not a mask class id")
        maps = [m for m, _ in self.class_pairs]
        if len(set(maps)) != len(maps):
            raise ValueError("SreConfig.class_pairs: each map class may appear once")
        if not self.gate_px > 0 or self.reference_width_px <= 0:
            raise ValueError("SreConfig: gate_px and reference_width_px must be > 0")
        if self.min_skeleton_px < 1 or self.min_projected_length_px < 0:
            raise ValueError("SreConfig: min_skeleton_px >= 1 and min_projected_length_px >= 0 required")

    def scale(self, width_px: int) -> float:
        """Factor from reference-width pixels to pixels of an image `width_px` wide."""
        return width_px / self.reference_width_px


@dataclass(frozen=True, eq=False)
class ProjectedInstance:
    """A map element as seen in one image: its visible pieces."""

    element_id: str
    map_class: str
    pieces: tuple[ProjectedPiece, ...]


@dataclass(frozen=True, eq=False)
class ImageInstance:
    """A lane instance of an instance mask, skeletonised."""

    value: int
    """Instance mask value (class * 1000 + index)."""
    mask_class: int
    """Semantic id of the instance."""
    skeleton_px: np.ndarray
    """(K, 2) skeleton pixel coordinates [u = column, v = row]."""


@dataclass(frozen=True)
class MatchedPair:
    """One Hungarian match and its error."""

    element_id: str
    instance_value: int
    error_px: float
    """Mean skeleton-pixel-to-curve distance in the image's own pixels."""


@dataclass(frozen=True)
class ImageMatch:
    """Matching outcome of one image."""

    projected: int
    """Projected instances considered."""
    image_instances: int
    """Image instances considered."""
    pairs: tuple[MatchedPair, ...]


def extract_instances(
    instance_mask: np.ndarray, mask_classes: set[int], min_skeleton_px: int
) -> list[ImageInstance]:
    """Skeletonised instances of the given classes of a (H, W) instance mask (value = class * 1000 + index)."""
    if instance_mask.ndim != 2:
        raise ValueError(f"instance mask must be 2D, got shape {instance_mask.shape}")
    out = []
    for value in np.unique(instance_mask):
        mask_class = int(value) // INSTANCE_ID_BASE
        if value == 0 or mask_class not in mask_classes:
            continue
        rows, cols = np.nonzero(instance_mask == value)
        r0, c0 = rows.min(), cols.min()
        crop = np.zeros((rows.max() - r0 + 3, cols.max() - c0 + 3), bool)
        crop[rows - r0 + 1, cols - c0 + 1] = True
        sk_rows, sk_cols = np.nonzero(skeletonize(crop))
        if sk_rows.size >= min_skeleton_px:
            skeleton = np.column_stack([sk_cols + c0 - 1, sk_rows + r0 - 1]).astype(np.float64)
            out.append(ImageInstance(int(value), mask_class, skeleton))
    return out


def curve_distances(
    points: np.ndarray, pieces: tuple[ProjectedPiece, ...], ignore_open_ends: bool
) -> np.ndarray:
    """Distance of each (K, 2) point to the nearest piece; NaN where the nearest point lies past an open end."""
    starts = np.vstack([p.points_px[:-1] for p in pieces])
    ends = np.vstack([p.points_px[1:] for p in pieces])
    open_before = np.zeros(len(starts), bool)
    open_after = np.zeros(len(starts), bool)
    offset = 0
    for p in pieces:
        n = len(p.points_px) - 1
        open_before[offset] = p.start_open
        open_after[offset + n - 1] = p.end_open
        offset += n
    direction = ends - starts
    length2 = np.maximum((direction**2).sum(axis=1), 1e-12)
    out = np.empty(len(points))
    step = max(1, _CHUNK // len(starts))
    for k in range(0, len(points), step):
        chunk = points[k : k + step]
        rel = chunk[:, None, :] - starts[None, :, :]
        t = (rel * direction[None]).sum(axis=2) / length2[None]
        foot = starts[None] + np.clip(t, 0.0, 1.0)[..., None] * direction[None]
        dist = np.linalg.norm(chunk[:, None, :] - foot, axis=2)
        nearest = dist.argmin(axis=1)
        rows = np.arange(len(chunk))
        best = dist[rows, nearest]
        if ignore_open_ends:
            t_best = t[rows, nearest]
            past = (open_before[nearest] & (t_best < 0)) | (open_after[nearest] & (t_best > 1))
            best = np.where(past, np.nan, best)
        out[k : k + step] = best
    return out


def pair_cost(
    instance: ImageInstance, projected: ProjectedInstance, min_points: int, ignore_open_ends: bool
) -> float:
    """Mean skeleton-to-curve distance of a pair (pixels); inf when fewer than `min_points` pixels count."""
    distances = curve_distances(instance.skeleton_px, projected.pieces, ignore_open_ends)
    valid = distances[np.isfinite(distances)]
    return float(valid.mean()) if valid.size >= min_points else float("inf")


def match_image(
    projected: list[ProjectedInstance], instances: list[ImageInstance], config: SreConfig, width_px: int
) -> ImageMatch:
    """Hungarian matching of one image's projected and image instances, class pair by class pair."""
    scale = config.scale(width_px)
    gate = config.gate_px * scale
    min_points = max(1, round(config.min_skeleton_px * scale))
    min_length = config.min_projected_length_px * scale
    kept_projected = [p for p in projected if sum(_length(q.points_px) for q in p.pieces) >= min_length]
    pairs: list[MatchedPair] = []
    for map_class, mask_class in config.class_pairs:
        rows = [p for p in kept_projected if p.map_class == map_class]
        cols = [i for i in instances if i.mask_class == int(mask_class)]
        if not rows or not cols:
            continue
        cost = np.array(
            [[pair_cost(i, p, min_points, config.ignore_beyond_range) for i in cols] for p in rows]
        )
        gated = np.where(cost <= gate, cost, gate * 100 + 1e6)
        for r, c in zip(*linear_sum_assignment(gated), strict=True):
            if cost[r, c] <= gate:
                pairs.append(MatchedPair(rows[r].element_id, cols[c].value, float(cost[r, c])))
    image_classes = {int(m) for _, m in config.class_pairs}
    map_classes = {m for m, _ in config.class_pairs}
    return ImageMatch(
        projected=sum(p.map_class in map_classes for p in kept_projected),
        image_instances=sum(i.mask_class in image_classes for i in instances),
        pairs=tuple(pairs),
    )


def _length(points: np.ndarray) -> float:
    """Length of a polyline in pixels."""
    return float(np.linalg.norm(np.diff(points, axis=0), axis=1).sum())
