"""Pose and elevation error figures against ground truth, shared by the benchmarks."""

import logging
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np

from cama_pipeline.data import Pose

logger = logging.getLogger(__name__)

Alignment = Literal["none", "se3", "sim3"]


@dataclass(frozen=True)
class PoseErrors:
    """Errors of an estimated pose sequence against the true one."""

    position_rmse_m: float
    """RMSE of translation differences, unaligned."""
    rotation_rmse_deg: float
    """RMSE of the relative rotation angles, unaligned."""
    heading_rmse_deg: float
    """RMSE of yaw differences (wrapped to [-180, 180)), unaligned."""
    ate_m: float
    """Absolute trajectory error: position RMSE after `alignment`."""
    alignment: Alignment
    count: int


@dataclass(frozen=True)
class ElevationErrors:
    """Errors of an elevation raster against the true one over the evaluated cells."""

    rmse_m: float
    mae_m: float
    bias_m: float
    """Mean of estimated - true."""
    max_abs_m: float
    count: int
    """Cells evaluated (in the mask and finite in both rasters)."""


def rotation_angles_deg(estimated: np.ndarray, true: np.ndarray) -> np.ndarray:
    """Angle (degrees) of R_true^T R_est for each pair of (N, 3, 3) rotation matrices."""
    relative = np.einsum("nji,njk->nik", true, estimated)
    cos = (np.trace(relative, axis1=1, axis2=2) - 1) / 2
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


def headings_deg(rotations: np.ndarray) -> np.ndarray:
    """Yaw (degrees, counter-clockwise from global x) of the x axis of each (N, 3, 3) rotation."""
    return np.degrees(np.arctan2(rotations[:, 1, 0], rotations[:, 0, 0]))


def umeyama_alignment(
    source: np.ndarray, target: np.ndarray, *, with_scale: bool
) -> tuple[np.ndarray, np.ndarray, float]:
    """(R, t, s) minimising |s R source + t - target|^2 over (N, 3) point sets (Umeyama 1991)."""
    mu_s, mu_t = source.mean(axis=0), target.mean(axis=0)
    src, dst = source - mu_s, target - mu_t
    u, sigma, vt = np.linalg.svd(dst.T @ src / len(source))
    sign = np.eye(3)
    if np.linalg.det(u) * np.linalg.det(vt) < 0:
        sign[2, 2] = -1
    rotation = u @ sign @ vt
    variance = (src**2).sum() / len(source)
    scale = float(np.trace(np.diag(sigma) @ sign) / variance) if with_scale and variance > 0 else 1.0
    return rotation, mu_t - scale * rotation @ mu_s, scale


def pose_errors(
    estimated: Sequence[Pose], true: Sequence[Pose], *, alignment: Alignment = "none"
) -> PoseErrors:
    """Position, rotation and heading RMSE and ATE of `estimated` against `true` global_from_ego poses."""
    if len(estimated) != len(true) or not estimated:
        raise ValueError(
            f"pose sequences must be non-empty and equally long, got {len(estimated)} and {len(true)}"
        )
    if alignment not in ("none", "se3", "sim3"):
        raise ValueError(f"alignment must be 'none', 'se3' or 'sim3', got {alignment!r}")
    if alignment != "none" and len(estimated) < 3:
        raise ValueError(f"alignment {alignment!r} needs at least 3 poses, got {len(estimated)}")
    t_est = np.array([p.translation for p in estimated])
    t_true = np.array([p.translation for p in true])
    r_est = np.array([p.rotation_matrix() for p in estimated])
    r_true = np.array([p.rotation_matrix() for p in true])
    heading = (headings_deg(r_est) - headings_deg(r_true) + 180.0) % 360.0 - 180.0
    aligned = t_est
    if alignment != "none":
        rotation, translation, scale = umeyama_alignment(t_est, t_true, with_scale=alignment == "sim3")
        aligned = scale * t_est @ rotation.T + translation
    return PoseErrors(
        position_rmse_m=_rms(np.linalg.norm(t_est - t_true, axis=1)),
        rotation_rmse_deg=_rms(rotation_angles_deg(r_est, r_true)),
        heading_rmse_deg=_rms(heading),
        ate_m=_rms(np.linalg.norm(aligned - t_true, axis=1)),
        alignment=alignment,
        count=len(estimated),
    )


def elevation_errors(
    estimated: np.ndarray, true: np.ndarray, mask: np.ndarray | None = None
) -> ElevationErrors:
    """RMSE / MAE / bias / max of estimated - true elevation over `mask` cells finite in both rasters."""
    estimated, true = np.asarray(estimated, dtype=np.float64), np.asarray(true, dtype=np.float64)
    if estimated.shape != true.shape or estimated.ndim != 2:
        raise ValueError(
            f"elevation rasters must be 2D and the same shape, got {estimated.shape} and {true.shape}"
        )
    valid = np.isfinite(estimated) & np.isfinite(true)
    if mask is not None:
        mask = np.asarray(mask)
        if mask.shape != true.shape:
            raise ValueError(f"mask shape {mask.shape} differs from the rasters' {true.shape}")
        valid &= mask.astype(bool)
    if not valid.any():
        raise ValueError("no cell to evaluate: the mask is empty or the rasters are not finite there")
    diff = estimated[valid] - true[valid]
    return ElevationErrors(
        rmse_m=_rms(diff),
        mae_m=float(np.abs(diff).mean()),
        bias_m=float(diff.mean()),
        max_abs_m=float(np.abs(diff).max()),
        count=int(valid.sum()),
    )


def _rms(values: np.ndarray) -> float:
    """Root mean square."""
    return float(np.sqrt(np.mean(np.square(values))))
