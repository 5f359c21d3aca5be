"""What a feature extractor and a pair matcher provide, so a learned pair (SuperPoint/LightGlue-style) can
replace SIFT and COLMAP's matcher without changing the stage that calls them."""

from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import numpy as np


@dataclass(frozen=True, eq=False)
class Features:
    """Keypoints and descriptors of one image."""

    keypoints: np.ndarray
    """(N, 6) float32: x, y (pixels) and the affine shape a11, a12, a21, a22, as COLMAP stores them."""
    descriptors: np.ndarray
    """(N, D) uint8."""

    def __post_init__(self) -> None:
        if self.keypoints.ndim != 2 or self.keypoints.shape[1] != 6:
            raise ValueError(f"keypoints must be (N, 6), got {self.keypoints.shape}")
        if len(self.descriptors) != len(self.keypoints):
            raise ValueError(f"{len(self.keypoints)} keypoints but {len(self.descriptors)} descriptors")

    def subset(self, keep: np.ndarray) -> "Features":
        """The features where `keep` is True."""
        return Features(self.keypoints[keep], self.descriptors[keep])


class FeatureExtractor(Protocol):
    """Turns a grey image into features; `name` is recorded with the database so mixed runs are refused."""

    name: str

    def extract(self, gray: np.ndarray) -> Features:
        """Features of an (H, W) uint8 image."""
        ...


class PairMatcher(Protocol):
    """Matches and geometrically verifies the listed pairs of a COLMAP database in place."""

    name: str

    def match(self, database: Path, pairs_file: Path) -> None:
        """Match every "nameA nameB" line of `pairs_file` that the database has not matched yet."""
        ...
