"""Parameters of feature extraction, masking and matching in one frozen, validated config."""

from dataclasses import dataclass, field
from typing import Literal

from cama_pipeline.segment.ego import EgoConfig
from cama_pipeline.semantics import Semantic


@dataclass(frozen=True)
class FeaturesConfig:
    """What is extracted where, and how pairs are matched and verified."""

    max_num_features: int = 4096
    """SIFT keypoints kept per image at most."""
    first_octave: int | None = None
    """SIFT's first octave; None: `octave_for_width` picks it per image, -1 (the image upsampled twice) for images
    narrower than `upsample_below_px`, else 0. 512 x 288 needs the upsampling for enough road features; at
    nuScenes' 1600 x 900 it would make SIFT search four times the image's pixels (README, "SIFT at the images' own
    scale")."""
    upsample_below_px: int = 1280
    """With `first_octave` None, images narrower than this are upsampled: every size measured before the choice
    (256 to 1024 pixels wide) keeps the upsampling it was measured with, and no image is searched at a finest scale
    coarser than a 1280-pixel-wide one's."""
    masked_classes: tuple[int, ...] = (int(Semantic.VEHICLE), int(Semantic.EGO))
    """Semantic classes whose pixels carry no features: moving/parked vehicles and the ego body."""
    mask_dilation_px: int = 9
    """Masked regions grow by this many pixels (SIFT support regions reach past object outlines)."""
    ego_from_clip: bool = True
    """When the masks label no ego pixel (or there are none), mask the ego body estimated from the pixels that stay
    constant through each clip (`ego`); masks that label it are used as they are."""
    ego: EgoConfig = field(default_factory=EgoConfig)
    """How the ego body is estimated from a clip (`cama_pipeline.segment.ego`)."""
    min_features_warning: int = 150
    """Images with fewer features than this are reported (night, blank or blurred images)."""
    max_ratio: float = 0.8
    """Lowe's ratio test of the matcher."""
    max_descriptor_distance: float = 0.7
    """Matches whose unit descriptors are further apart than this angle (radians) are dropped (COLMAP's)."""
    min_num_inliers: int = 15
    """Geometric verification keeps a pair only with at least this many inliers."""
    matcher: Literal["blas", "colmap"] = "blas"
    """Descriptor matching: "blas" (one matrix product per pair, `features/matching.py`: 5.2 ms of CPU per pair
    on the default site, 1,000 pairs) or "colmap" (COLMAP's CPU matcher: 17-20 ms); the same mutual ratio-test
    matches (731 vs 730 verified pairs of 1,000, median 106 inliers both). Verification is COLMAP's either way."""
    ransac_trials_multiplier: float = 1.0
    """RANSAC's adaptive trial count times this (COLMAP's default is 3): 1 cut verification from 5.0-5.8 to
    4.4 ms of CPU per pair on the default site with the same verified pairs and inliers (731 vs 732 of 1,000)."""
    ransac_seed: int = 0
    """The seed of each pair's verification RANSAC, so that a rerun verifies the same pairs with the same inliers
    (COLMAP's default, -1, seeds from the clock: two runs on one data set differed by a verified pair and moved
    the merged reconstruction by centimetres)."""
    num_threads: int = 2
    """Extraction processes and matching threads (pycolmap's SIFT holds the GIL, so extraction needs processes:
    2 processes extract the default site's 912 images in about half the time of one). The "colmap" matcher runs on
    one thread whatever this says, so that its reruns agree (`sift.ColmapMatcher`)."""

    def __post_init__(self) -> None:
        if self.max_num_features < 1:
            raise ValueError(f"FeaturesConfig.max_num_features must be >= 1, got {self.max_num_features}")
        if self.mask_dilation_px < 0:
            raise ValueError(f"FeaturesConfig.mask_dilation_px must be >= 0, got {self.mask_dilation_px}")
        if not 0 < self.max_descriptor_distance <= 2:
            raise ValueError(
                f"FeaturesConfig.max_descriptor_distance must be in (0, 2], got {self.max_descriptor_distance}"
            )
        if not 0 < self.max_ratio <= 1:
            raise ValueError(f"FeaturesConfig.max_ratio must be in (0, 1], got {self.max_ratio}")
        if self.min_num_inliers < 4:
            raise ValueError(f"FeaturesConfig.min_num_inliers must be >= 4, got {self.min_num_inliers}")
        if self.matcher not in ("blas", "colmap"):
            raise ValueError(f"FeaturesConfig.matcher must be 'blas' or 'colmap', got {self.matcher!r}")
        if not self.ransac_trials_multiplier > 0:
            raise ValueError(
                f"FeaturesConfig.ransac_trials_multiplier must be > 0, got {self.ransac_trials_multiplier}"
            )
        if self.ransac_seed < 0:
            raise ValueError(f"FeaturesConfig.ransac_seed must be >= 0, got {self.ransac_seed}")
        if self.num_threads < 1:
            raise ValueError(f"FeaturesConfig.num_threads must be >= 1, got {self.num_threads}")
        if self.first_octave is not None and (
            isinstance(self.first_octave, bool)
            or not isinstance(self.first_octave, int)
            or self.first_octave < -1
        ):
            raise ValueError(
                f"FeaturesConfig.first_octave must be None or an integer >= -1, got {self.first_octave!r}"
            )
        if self.upsample_below_px < 1:
            raise ValueError(f"FeaturesConfig.upsample_below_px must be >= 1, got {self.upsample_below_px}")

    def octave_for_width(self, width_px: int) -> int:
        """SIFT's first octave for an image `width_px` wide (`first_octave`)."""
        if self.first_octave is not None:
            return self.first_octave
        return -1 if width_px < self.upsample_below_px else 0
