"""Photometric agreement of a reconstructed BEV colour raster with the true albedo (8-bit RGB values).

The surface's colour comes from shaded, exposed images and the synthetic truth is albedo, so the benches report the
PSNR as it is and after the per-channel gain and offset that fits it best (`affine_fit`).
"""

import numpy as np


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    """Peak signal-to-noise ratio (dB) of `a` against `b`, values 0-255."""
    return psnr_of_mse(float(np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2)))


def psnr_of_mse(mse: float) -> float:
    """PSNR (dB) of a mean squared error of 0-255 values."""
    return float(10 * np.log10(255.0**2 / max(mse, 1e-12)))


def affine_fit(ours: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """`ours` (N, 3) mapped per channel by the least-squares gain and offset onto `truth`."""
    fitted = np.empty_like(ours, dtype=np.float64)
    for ch in range(3):
        design = np.column_stack([ours[:, ch], np.ones(len(ours))]).astype(np.float64)
        coef, *_ = np.linalg.lstsq(design, truth[:, ch].astype(np.float64), rcond=None)
        fitted[:, ch] = np.clip(design @ coef, 0, 255)
    return fitted
