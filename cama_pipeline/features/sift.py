"""SIFT through pycolmap (CPU; COLMAP's GPU SIFT when built with it) and COLMAP's matcher on a pair list."""

from pathlib import Path

import numpy as np
import pycolmap

from cama_pipeline.features.config import FeaturesConfig
from cama_pipeline.features.interface import Features

SIFT_DIMENSIONS = 128


class SiftExtractor:
    """COLMAP SIFT with this project's options; pickles as its config, so extraction processes rebuild it."""

    name = "colmap-sift"

    def __init__(self, config: FeaturesConfig) -> None:
        self._config = config
        self._by_octave: dict[int, pycolmap.FeatureExtractor] = {}

    def _extractor(self, width_px: int) -> pycolmap.FeatureExtractor:
        """COLMAP's extractor with the first octave for images `width_px` wide, made on first use."""
        octave = self._config.octave_for_width(width_px)
        if octave not in self._by_octave:
            options = pycolmap.FeatureExtractionOptions()
            options.num_threads = self._config.num_threads
            options.sift.max_num_features = self._config.max_num_features
            options.sift.first_octave = octave
            self._by_octave[octave] = pycolmap.FeatureExtractor.create(options, device=pycolmap.Device.cpu)
        return self._by_octave[octave]

    def __getstate__(self) -> FeaturesConfig:
        return self._config

    def __setstate__(self, config: FeaturesConfig) -> None:
        self.__init__(config)  # type: ignore[misc]

    def extract(self, gray: np.ndarray) -> Features:
        """SIFT keypoints (with affine shape) and uint8 descriptors of a grey image."""
        extractor = self._extractor(gray.shape[1])
        keypoints, descriptors = extractor.extract_from_uint8_array(np.ascontiguousarray(gray))
        shape = np.array([[k.x, k.y, k.a11, k.a12, k.a21, k.a22] for k in keypoints], dtype=np.float32)
        data = np.asarray(descriptors.data, dtype=np.uint8).reshape(len(shape), SIFT_DIMENSIONS)
        return Features(shape.reshape(-1, 6), data)


def verification_options(config: FeaturesConfig) -> pycolmap.TwoViewGeometryOptions:
    """COLMAP's two-view geometric verification with this project's inlier floor, RANSAC trial count and seed."""
    options = pycolmap.TwoViewGeometryOptions()
    options.min_num_inliers = config.min_num_inliers
    options.ransac.dyn_num_trials_multiplier = config.ransac_trials_multiplier
    options.ransac.random_seed = config.ransac_seed
    return options


class ColmapMatcher:
    """COLMAP's nearest-neighbour matcher with ratio and cross check, then two-view geometric verification.

    It runs on one thread whatever `FeaturesConfig.num_threads` says: on two threads the same features matched
    and verified twice differed in 3 of 40 reruns on one tiny site (a pair verified with 238 inliers in one run and
    94 in the next, or not at all), so a rerun did not reconstruct the same site despite the RANSAC seed; on one
    thread 60 of 60 reruns were identical. The default matcher ("blas") keeps its threads: its reruns are
    identical."""

    name = "colmap-nn"

    def __init__(self, config: FeaturesConfig) -> None:
        self._matching = pycolmap.FeatureMatchingOptions()
        self._matching.num_threads = 1
        self._matching.sift.max_ratio = config.max_ratio
        self._verification = verification_options(config)

    def match(self, database: Path, pairs_file: Path) -> None:
        """Match the listed pairs (COLMAP skips pairs the database already holds)."""
        pairing = pycolmap.ImportedPairingOptions()
        pairing.match_list_path = str(pairs_file)
        pycolmap.match_image_pairs(
            str(database),
            matching_options=self._matching,
            pairing_options=pairing,
            verification_options=self._verification,
            device=pycolmap.Device.cpu,
        )
