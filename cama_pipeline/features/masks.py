"""Feature masks: where no keypoint may lie (the ego body and vehicles, from the semantic masks, dilated), with the
ego body estimated from the clip when the masks label none (`cama_pipeline.segment.ego`)."""

from collections.abc import Sequence

import cv2
import numpy as np

from cama_pipeline.cameras import CameraView
from cama_pipeline.data import Dataset
from cama_pipeline.segment.ego import EgoConfig, estimate_ego_mask
from cama_pipeline.semantics import Semantic


def blocked_pixels(semantic: np.ndarray, classes: tuple[int, ...], dilation_px: int) -> np.ndarray:
    """(H, W) bool: True on pixels of `classes`, grown by `dilation_px` (an elliptic structuring element)."""
    blocked = np.isin(semantic, classes)
    if dilation_px > 0 and blocked.any():
        size = 2 * dilation_px + 1
        kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (size, size))
        blocked = cv2.dilate(blocked.astype(np.uint8), kernel).astype(bool)
    return np.asarray(blocked)


def keypoints_allowed(keypoints_xy: np.ndarray, blocked: np.ndarray) -> np.ndarray:
    """(N,) bool: keypoints (x, y pixel coordinates, pixel centres at integers) outside blocked pixels."""
    if len(keypoints_xy) == 0:
        return np.zeros(0, dtype=bool)
    height, width = blocked.shape
    cols = np.clip(np.round(keypoints_xy[:, 0]).astype(int), 0, width - 1)
    rows = np.clip(np.round(keypoints_xy[:, 1]).astype(int), 0, height - 1)
    return np.asarray(~blocked[rows, cols])


def masks_label_ego(dataset: Dataset, views: Sequence[CameraView], per_channel: int = 2) -> bool:
    """Whether the masks label the ego body: a few masks of each camera (the first `per_channel` views of each
    channel that have one) are read, and any EGO pixel says yes. Masks made by a source that knows the class
    (the generator, the segmenter, Vistas, Cityscapes' labelIds) have it in the cameras that see the body."""
    read: dict[str, int] = {}
    for view in views:
        image = dataset.image(view.token)
        if image.semantic_mask_path is None or read.get(view.channel, 0) >= per_channel:
            continue
        read[view.channel] = read.get(view.channel, 0) + 1
        if (image.load_semantic() == Semantic.EGO).any():
            return True
    return False


def ego_estimates(
    dataset: Dataset, views: Sequence[CameraView], config: EgoConfig
) -> dict[tuple[str, str], np.ndarray]:
    """The ego body of each (scene, channel) of `views` from the pixels that stay constant through the scene
    (`cama_pipeline.segment.ego`, on every image of the scene's camera). A scene that cannot tell (standing, night)
    takes the body found in another scene of the same camera (the same calibrated_sensor: the body does not move
    on the car); pairs left without an estimate are left out."""
    estimates: dict[tuple[str, str], np.ndarray] = {}
    calibration: dict[tuple[str, str], str] = {}
    for scene, channel in sorted({(view.scene, view.channel) for view in views}):
        images = dataset.scene_by_name(scene).images.get(channel, ())
        if images:
            calibration[(scene, channel)] = images[0].calibration.token
        estimate = estimate_ego_mask(images, config)
        if estimate is not None:
            estimates[(scene, channel)] = estimate
    by_camera = {calibration[key]: mask for key, mask in estimates.items() if key in calibration}
    for key, token in calibration.items():
        if key not in estimates and token in by_camera:
            estimates[key] = by_camera[token]
    return estimates


def feature_block(
    semantic: np.ndarray | None, ego: np.ndarray | None, classes: tuple[int, ...], dilation_px: int
) -> np.ndarray | None:
    """Pixels where no keypoint may lie: the mask's `classes`, and the estimated ego body `ego` when EGO is one of
    them and the mask has no EGO pixel (or there is no mask), grown by `dilation_px`; None: no mask, no estimate."""
    if ego is not None and int(Semantic.EGO) not in classes:
        ego = None
    if semantic is None:
        if ego is None:
            return None
        semantic = np.zeros(ego.shape, np.uint8)
    if ego is not None and not (semantic == Semantic.EGO).any():
        if ego.shape != semantic.shape:
            raise ValueError(
                f"ego body estimate is {ego.shape[1]}x{ego.shape[0]} px, the mask {semantic.shape}"
            )
        semantic = np.where(ego, np.uint8(Semantic.EGO), semantic)
    return blocked_pixels(semantic, classes, dilation_px)
