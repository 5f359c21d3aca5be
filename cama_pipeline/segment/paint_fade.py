"""Extra paint wear on a training image: its markings faded toward the surface they are painted on.

The generator draws each site's paint fade uniformly in 0-0.45 (`synthetic.randomise`), so a training set of a
few dozen sites holds only a handful of heavily faded ones. Fading the paint of a training crop makes more of
them (`cama train-segmenter --paint-fade-max`; measured, it did not lift the lane markings of heavily faded
sites, README "More sites, and extra paint fade", so it is off by default), the way the generator itself fades
paint: the image moves from the paint toward the surface under it by a share `fade`
(`synthetic.shading` scales the paint's opacity by 1 - fade). The surface under the paint is not known from the
image, so it is filled in from the unpainted pixels around (OpenCV's fast-marching inpainting). The mask stays:
a faded line is still the whole line, as an annotator draws it.
"""

import cv2
import numpy as np

from cama_pipeline.semantics import Semantic

PAINT_CLASSES = (int(Semantic.LANE_MARKING), int(Semantic.CROSSWALK))
"""Mask classes whose pixels are paint."""
INPAINT_RADIUS_PX = 5
"""Neighbourhood the surface colour under the paint is filled in from."""


def paint_region(mask: np.ndarray) -> np.ndarray:
    """The painted pixels of `mask` (H, W class ids) grown by one pixel, as uint8 0/255: paint's anti-aliased
    edge also covers the road pixels touching it."""
    painted = np.isin(mask, PAINT_CLASSES).astype(np.uint8) * 255
    return cv2.dilate(painted, np.ones((3, 3), np.uint8))


def fade_paint(image: np.ndarray, mask: np.ndarray, fade: float) -> np.ndarray:
    """`image` (H, W, 3 uint8) with its paint (per `mask`) moved a share `fade` (0..1) toward the surface under
    it; the same image when nothing is painted or `fade` is 0."""
    if not 0.0 <= fade <= 1.0:
        raise ValueError(f"paint fade must be in [0, 1], got {fade!r}")
    if image.shape[:2] != mask.shape:
        raise ValueError(f"image {image.shape[:2]} and mask {mask.shape} differ in size")
    region = paint_region(mask)
    if fade == 0.0 or not region.any():
        return image
    image = np.ascontiguousarray(image)
    surface = cv2.inpaint(image, region, INPAINT_RADIUS_PX, cv2.INPAINT_TELEA).astype(np.float32)
    faded = surface + (image.astype(np.float32) - surface) * (1.0 - fade)
    inside = region.astype(bool)
    out = image.copy()
    out[inside] = np.clip(np.rint(faded[inside]), 0, 255).astype(np.uint8)
    return out
