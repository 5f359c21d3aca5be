"""The model's placement in the global frame (its gauge), fitted to every odometry pose at once.

BA fixes the model's shape to millimetres, but its placement is only as good as what holds it: a few
poses, or priors on each frame that the relative constraints outweigh. WIGO's error is a slow drift per
clip (decimetres, nearly constant over a clip, different between clips), so the placement that best fits
*all* odometry poses averages it over clips. The rigid fit is a rotation about the model's centre and a
shift, by weighted least squares on camera positions and orientations, the orientations split into tilt
(well known from gravity) and heading (poorly known). With `fit_scale` (the pipeline's default,
`SfmConfig.gauge_fit_scale`) it also scales the model about its centre: the images fix each clip's scale
only to about 0.1 % with this rig (and bias it the same way in every clip), while the odometry's scale
error differs per clip and averages out over a site's clips.
"""

import logging
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import pycolmap
from scipy.spatial.transform import Rotation

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class GaugeSigmas:
    """Relative weights of the fit: 1-sigma of the odometry's position, tilt and heading."""

    position_m: float
    tilt_deg: float
    heading_deg: float

    def __post_init__(self) -> None:
        for name in ("position_m", "tilt_deg", "heading_deg"):
            if not getattr(self, name) > 0:
                raise ValueError(f"GaugeSigmas.{name} must be > 0, got {getattr(self, name)}")


@dataclass(frozen=True)
class GaugeFit:
    """The correction (rigid, or a similarity with `fit_scale`) that moves the model onto the odometry, and
    how large it is."""

    new_from_old: np.ndarray
    """(4, 4) transform of the global frame: scale times rotation, and translation."""
    poses: int
    """Poses the fit used."""
    shift_m: float
    """How far the model's centre moved."""
    rotation_deg: float
    scale: float = 1.0
    """The model's scale change (1 for a rigid fit)."""

    def move_pose(self, world_from_x: np.ndarray) -> np.ndarray:
        """A (4, 4) pose of the model moved by the fit: its position by the whole transform, its orientation
        by the rotation alone. (A scaled model's cameras sit (scale - 1) x their lever arm from the moved ego
        pose's cameras: about 2 mm at a 0.1 % scale.)"""
        moved = self.new_from_old @ world_from_x
        moved[:3, :3] /= self.scale
        return moved

    def to_json(self) -> dict[str, Any]:
        return {
            "poses": self.poses,
            "shift_m": self.shift_m,
            "rotation_deg": self.rotation_deg,
            "scale": self.scale,
        }


def _skew(v: np.ndarray) -> np.ndarray:
    """(N, 3, 3) cross-product matrices of (N, 3) vectors."""
    out = np.zeros((len(v), 3, 3))
    out[:, 0, 1], out[:, 0, 2], out[:, 1, 2] = -v[:, 2], v[:, 1], -v[:, 0]
    return out - out.transpose(0, 2, 1)


def _step(
    similarity: tuple[float, np.ndarray, np.ndarray],
    offsets: np.ndarray,
    targets: np.ndarray,
    residual_rotations: np.ndarray,
    sigmas: GaugeSigmas,
    fit_scale: bool,
) -> np.ndarray:
    """One Gauss-Newton step [d_rotvec, d_shift(, d_log_scale)] of the weighted fit (left perturbation about
    the centre)."""
    scale, rotation, shift = similarity
    moved = scale * offsets @ rotation.T + shift
    columns = [-_skew(moved - shift), np.broadcast_to(np.eye(3), moved.shape + (3,))]
    if fit_scale:
        columns.append((moved - shift)[:, :, None])
    position_jacobian = np.concatenate(columns, 2)
    position_weight = 1.0 / sigmas.position_m**2
    rotation_weight = np.diag(
        [math.radians(sigmas.tilt_deg) ** -2] * 2 + [math.radians(sigmas.heading_deg) ** -2]
    )
    normal = position_weight * np.einsum("nij,nik->jk", position_jacobian, position_jacobian)
    rhs = position_weight * np.einsum("nij,ni->j", position_jacobian, targets - moved)
    normal[:3, :3] += len(offsets) * rotation_weight
    rhs[:3] += rotation_weight @ residual_rotations.sum(axis=0)
    return np.asarray(np.linalg.solve(normal, rhs))


def fit_gauge(
    estimated: Mapping[str, np.ndarray],
    odometry: Mapping[str, np.ndarray],
    sigmas: GaugeSigmas,
    *,
    fit_scale: bool = False,
) -> GaugeFit | None:
    """The rigid correction (a similarity with `fit_scale`) that best moves the `estimated` (4, 4) poses onto
    the `odometry` ones (world_from_x by name; names in both count); None when fewer than 3 poses are
    shared."""
    names = sorted(set(estimated) & set(odometry))
    if len(names) < 3:
        return None
    centres = np.array([estimated[n][:3, 3] for n in names])
    centre = centres.mean(axis=0)
    offsets, targets = centres - centre, np.array([odometry[n][:3, 3] for n in names]) - centre
    odometry_rotations = np.array([odometry[n][:3, :3] for n in names])
    estimated_rotations = np.array([estimated[n][:3, :3] for n in names])
    scale, rotation, shift = 1.0, np.eye(3), np.zeros(3)
    for _ in range(3):  # the correction is tiny: converges in one or two steps
        residual = Rotation.from_matrix(
            odometry_rotations @ np.transpose(rotation @ estimated_rotations, (0, 2, 1))
        ).as_rotvec()
        delta = _step((scale, rotation, shift), offsets, targets, residual, sigmas, fit_scale)
        rotation = Rotation.from_rotvec(delta[:3]).as_matrix() @ rotation
        shift = shift + delta[3:6]
        if fit_scale:
            scale *= math.exp(delta[6])
    new_from_old = np.eye(4)
    new_from_old[:3, :3] = scale * rotation
    new_from_old[:3, 3] = centre + shift - scale * rotation @ centre
    angle = float(np.degrees(Rotation.from_matrix(rotation).magnitude()))
    return GaugeFit(new_from_old, len(names), float(np.linalg.norm(shift)), angle, scale)


def apply_gauge(reconstruction: pycolmap.Reconstruction, new_from_old: np.ndarray) -> None:
    """Move the model (its frames and points) by a rigid or similarity transform of the global frame, in
    place."""
    reconstruction.transform(pycolmap.Sim3d(np.asarray(new_from_old, float)[:3, :4]))
