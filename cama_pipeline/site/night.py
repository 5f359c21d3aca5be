"""Night detection: the scene's metadata first (nuScenes writes "night" in the description), else the
brightness of a few of its key-frame images. Night scenes are left out of sites (CAMAv2: the ground is
hardly visible and they spoil the day reconstruction)."""

import logging

import cv2
import numpy as np

from cama_pipeline.data import DatasetError, Scene
from cama_pipeline.site.config import SiteConfig

logger = logging.getLogger(__name__)


def mean_brightness(scene: Scene, count: int) -> float | None:
    """Mean 8-bit luma of up to `count` key-frame images spread over the clip; None if none can be read."""
    images = [im for frame in scene.frames for im in frame.images.values()]
    if not images:
        return None
    picks = sorted({int(i) for i in np.linspace(0, len(images) - 1, count)})
    values = []
    for i in picks:
        try:
            rgb = images[i].load_rgb()
        except DatasetError as err:
            logger.warning("scene %s: brightness check skips an image: %s", scene.name, err)
            continue
        values.append(float(cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY).mean()))
    return float(np.mean(values)) if values else None


def night_reason(scene: Scene, config: SiteConfig) -> str | None:
    """Why `scene` is a night scene, or None when it is a day scene."""
    description = scene.description.lower()
    for word in config.night_keywords:
        if word.lower() in description:
            return f"night: description {scene.description!r} says {word!r}"
    brightness = mean_brightness(scene, config.brightness_images)
    if brightness is None:
        logger.warning("scene %s: no readable key-frame image, night check by metadata only", scene.name)
        return None
    if brightness < config.night_brightness:
        return f"night: mean image brightness {brightness:.1f} < {config.night_brightness:g} (8-bit luma)"
    return None
