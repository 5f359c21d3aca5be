"""What the camera does to a rendered image before it is written: optical blur and sensor noise.

The renderer's output is an ideal pinhole image; real cameras blur it slightly (focus, lens, motion) and add
noise. Both are off by default (`CameraConfig`), so a default site's images are the renderer's own.
"""

import cv2
import numpy as np

from cama_pipeline.synthetic.config import CameraConfig


def apply_camera_effects(rgb: np.ndarray, camera: CameraConfig, rng: np.random.Generator) -> np.ndarray:
    """`rgb` (H, W, 3) float32 in linear [0, 1] blurred by `camera.blur_sigma_px` and given white Gaussian
    noise of `camera.noise_sigma`; returned unchanged (the same array) when both are 0."""
    if camera.blur_sigma_px > 0:
        rgb = cv2.GaussianBlur(rgb, (0, 0), sigmaX=camera.blur_sigma_px, borderType=cv2.BORDER_REFLECT)
    if camera.noise_sigma > 0:
        rgb = rgb + rng.normal(0.0, camera.noise_sigma, size=rgb.shape).astype(np.float32)
    return rgb
