"""Anchor queries of the hybrid VMA model: rule-based candidates as the decoder's initial instance queries.

MapTR learns its instance queries from scratch; on 2 CPU cores that does not converge in minutes (checkpoint
v0001: 40 min of training, mAP 0.004). The anchored variant (`ModelConfig.anchored`) starts each instance
query from one candidate of the rule-based proposer: the candidate's fixed points (normalised to the patch)
are the query's reference points, and its class, rule confidence and points are embedded into the query.
The network then learns the class scores (its confidence, and the rejection of false candidates by scoring
them low), point refinement and duplicate suppression, under the same Hungarian / permutation-equivalent
MapTR loss; slots no candidate fills stay free learned queries. When a patch holds more candidates than
queries, those of highest rule confidence x length are kept.
"""

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import torch

from annotations.geometry import resample_fixed
from models.vma.config import ModelConfig
from models.vma.vectors import CLASSES, Vector, clip_vectors

ANCHOR_FEATURES = len(CLASSES) + 2
"""Per query: class one-hot, rule confidence, and 1 when a candidate fills the slot."""


@dataclass(frozen=True, eq=False)
class Anchors:
    """The anchor queries of one patch."""

    points: np.ndarray
    """(Q, P, 2) float32 normalised patch coordinates (0 where no candidate)."""
    features: np.ndarray
    """(Q, ANCHOR_FEATURES) float32."""
    sources: np.ndarray
    """(Q,) int64 index of each slot's candidate in the given list, -1 where empty."""
    lengths: np.ndarray
    """(Q,) float64 length of each slot's clipped piece in patch pixels (0 where empty)."""


def patch_anchors(candidates: Sequence[Vector], config: ModelConfig, min_length_px: float) -> Anchors:
    """Anchors of candidates given in patch pixels (col, row; pixel centres at +0.5), clipped to the patch."""
    size = float(config.patch_px)
    pieces = [
        (piece, index)
        for index, candidate in enumerate(candidates)
        for piece in clip_vectors([candidate], (0.0, size, 0.0, size), min_length_px)
    ]
    pieces.sort(key=lambda p: -p[0].score * p[0].length_m())
    points = np.zeros((config.num_queries, config.num_points, 2), np.float32)
    features = np.zeros((config.num_queries, ANCHOR_FEATURES), np.float32)
    sources = np.full(config.num_queries, -1, np.int64)
    lengths = np.zeros(config.num_queries, np.float64)
    for k, (piece, index) in enumerate(pieces[: config.num_queries]):
        sources[k], lengths[k] = index, piece.length_m()
        points[k] = resample_fixed(piece.points, config.num_points) / size
        features[k, CLASSES.index(piece.cls)] = 1.0
        features[k, -2] = piece.score
        features[k, -1] = 1.0
    return Anchors(points, features, sources, lengths)


def stack_anchors(
    anchors: Sequence[Anchors | None], device: torch.device
) -> tuple[torch.Tensor, torch.Tensor] | None:
    """Batched (B, Q, P, 2) points and (B, Q, F) features, or None when the samples carry no anchors."""
    if not anchors or any(a is None for a in anchors):
        return None
    present = [a for a in anchors if a is not None]
    return (
        torch.as_tensor(np.stack([a.points for a in present]), device=device),
        torch.as_tensor(np.stack([a.features for a in present]), device=device),
    )
