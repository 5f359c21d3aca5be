"""The ego body (e.g. the trunk in CAM_BACK) of one camera when no mask labels it: the pixels that stay constant
through a clip while the car moves.

The scene moves through every other pixel of a moving car's camera, while the car's own body stays put in the
image. So, over frames picked at least `min_travel_m` apart, a pixel whose grey value hardly changes from one
picked frame to the next (median absolute change, after a light blur against sensor noise) is body, sky or a
featureless wall; the body is what of it touches the bottom edge of the image (sky and walls do not), in pieces
of at least `min_area_fraction` of the image. On the tiny site's CAM_BACK the estimate covers the generator's EGO
mask with IoU 0.99 (tests/segment/test_ego.py), and the other cameras get no ego pixel.

Used by the features stage when the masks label no ego pixel (Cityscapes' trainIds have no ego class; a data set
without masks and none imported or predicted); masks that label the ego body are used as they are.
Limits: a clip that does not move, or moves less than `min_frames` x `min_travel_m`, gives no estimate; a shiny
body reflecting the scene changes with it and is missed in part.
"""

import logging
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from cama_pipeline.data import CameraImage

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class EgoConfig:
    """How the ego body of a camera is estimated from a clip's frames."""

    max_frames: int = 16
    """Frames compared at most (picked evenly among those far enough apart)."""
    min_frames: int = 6
    """Fewer moving frames than this (a standing or short clip): no estimate."""
    min_travel_m: float = 0.5
    """Two compared frames are at least this far apart (coarse ego poses)."""
    max_change: float = 3.0
    """A pixel whose median absolute change between consecutive compared frames is at most this many grey levels
    (0-255) is constant (the tiny site's CAM_BACK: trunk pixels change by a median 0-1, 99% under 3; the road
    right behind the car by 1-3, in specks that `open_px` removes)."""
    blur_sigma_px: float = 0.0
    """Gaussian blur of the grey images before comparing them (against strong sensor noise; 0: none, the median
    over frame pairs already damps noise: on the tiny site a 0.7 px blur mixed trunk and road at the edge)."""
    min_area_fraction: float = 0.002
    """A piece of constant pixels touching the bottom edge counts only from this fraction of the image."""
    max_still_fraction: float = 0.6
    """When more of the lower half of the image than this stays constant, the clip cannot tell body from scene
    (night, fog, a blank image): no estimate. Tiny site: 0.05-0.40 by day, 0.69-0.91 at night."""
    open_px: int = 2
    """Constant specks thinner than about twice this are removed before the pieces are found."""

    def __post_init__(self) -> None:
        if self.min_frames < 3:
            raise ValueError(f"EgoConfig.min_frames must be >= 3, got {self.min_frames}")
        if self.max_frames < self.min_frames:
            raise ValueError(
                f"EgoConfig.max_frames must be >= min_frames ({self.min_frames}), got {self.max_frames}"
            )
        if not self.min_travel_m > 0:
            raise ValueError(f"EgoConfig.min_travel_m must be > 0, got {self.min_travel_m}")
        if not 0 < self.max_change < 255:
            raise ValueError(f"EgoConfig.max_change must be in (0, 255), got {self.max_change}")
        if self.blur_sigma_px < 0:
            raise ValueError(f"EgoConfig.blur_sigma_px must be >= 0, got {self.blur_sigma_px}")
        if not 0 <= self.min_area_fraction < 1:
            raise ValueError(f"EgoConfig.min_area_fraction must be in [0, 1), got {self.min_area_fraction}")
        if not 0 < self.max_still_fraction <= 1:
            raise ValueError(f"EgoConfig.max_still_fraction must be in (0, 1], got {self.max_still_fraction}")
        if self.open_px < 0:
            raise ValueError(f"EgoConfig.open_px must be >= 0, got {self.open_px}")


def moving_frames(images: Sequence[CameraImage], config: EgoConfig) -> list[CameraImage]:
    """Images of one camera of one clip (time order) at least `min_travel_m` apart, at most `max_frames` of them
    spread over the clip; empty when fewer than `min_frames` qualify."""
    picked: list[CameraImage] = []
    for image in sorted(images, key=lambda im: im.timestamp_us):
        position = image.global_from_ego.translation
        if picked and np.linalg.norm(position - picked[-1].global_from_ego.translation) < config.min_travel_m:
            continue
        picked.append(image)
    if len(picked) < config.min_frames:
        return []
    keep = np.unique(np.round(np.linspace(0, len(picked) - 1, config.max_frames)).astype(int))
    return [picked[i] for i in keep]


def constant_pixels(grey_frames: Sequence[np.ndarray], config: EgoConfig) -> np.ndarray:
    """(H, W) bool: pixels whose median absolute change between consecutive frames is at most `max_change`."""
    frames = []
    for grey in grey_frames:
        image = grey.astype(np.float32)
        if config.blur_sigma_px > 0:
            image = np.asarray(cv2.GaussianBlur(image, (0, 0), config.blur_sigma_px), np.float32)
        frames.append(image)
    changes = np.stack([np.abs(b - a) for a, b in zip(frames, frames[1:], strict=False)])
    return np.asarray(np.median(changes, axis=0) <= config.max_change)


def body_pieces(constant: np.ndarray, config: EgoConfig) -> np.ndarray:
    """(H, W) bool: the pieces of `constant` (after removing specks) that touch the bottom edge and are large
    enough, with their holes filled."""
    mask = constant.astype(np.uint8)
    if config.open_px > 0:
        size = 2 * config.open_px + 1
        kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (size, size))
        mask = np.asarray(cv2.morphologyEx(mask, cv2.MORPH_OPEN, kernel), np.uint8)
    count, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=4)
    height, width = mask.shape
    min_area = config.min_area_fraction * height * width
    bottom = set(np.unique(labels[-1])) - {0}
    keep = [i for i in bottom if stats[i, cv2.CC_STAT_AREA] >= min_area]
    body = np.isin(labels, keep)
    return _fill_holes(body)


def _fill_holes(mask: np.ndarray) -> np.ndarray:
    """`mask` with every region it encloses (not reachable from the border through non-mask pixels) set."""
    outside = (~mask).astype(np.uint8)
    count, labels = cv2.connectedComponents(outside, connectivity=4)
    border = set(np.unique(np.concatenate([labels[0], labels[-1], labels[:, 0], labels[:, -1]])))
    enclosed = ~np.isin(labels, list(border)) & (outside > 0)
    return np.asarray(mask | enclosed)


def estimate_ego_mask(images: Sequence[CameraImage], config: EgoConfig | None = None) -> np.ndarray | None:
    """(H, W) bool ego body of one camera from one clip's images of it (all of them: frames far enough apart are
    picked here); None when the clip does not move enough to tell (see `moving_frames`)."""
    config = config or EgoConfig()
    frames = moving_frames(images, config)
    if not frames:
        logger.info(
            "%s: under %d frames %.1f m apart, no ego body estimate",
            images[0].channel if images else "no images",
            config.min_frames,
            config.min_travel_m,
        )
        return None
    greys = [cv2.cvtColor(image.load_rgb(), cv2.COLOR_RGB2GRAY) for image in frames]
    constant = constant_pixels(greys, config)
    still = float(constant[constant.shape[0] // 2 :].mean())
    if still > config.max_still_fraction:
        logger.warning(
            "%s: %.0f%% of the lower half of the image stays constant through the clip (night, fog or a blank "
            "image?): no ego body estimate",
            frames[0].channel,
            100 * still,
        )
        return None
    return body_pieces(constant, config)
