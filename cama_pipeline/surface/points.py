"""Surface points initialisation: a narrow road strip under the ego trajectory plus the SfM road points.

The ego origin (nuScenes, and the synthetic generator) is the ground under the rear axle, so the strip is
the ego frame's z = 0 plane under the car body: road by construction, and never a moving object.
"""

import logging
from dataclasses import dataclass

import numpy as np

from cama_pipeline.cameras import CameraView
from cama_pipeline.semantics import ROAD_SURFACE_IDS
from cama_pipeline.sfm.io import read_points
from cama_pipeline.surface.config import SurfaceConfig
from cama_pipeline.workspace import Workspace

logger = logging.getLogger(__name__)

"""SfM point labels that lie on the road surface (not curb: a curb stands a kerb height above the road,
and pulls the surface up along the road edges)."""


class NoRoadPointsError(ValueError):
    """A site with no road surface point to fit the elevation to."""


@dataclass(frozen=True, eq=False)
class SurfacePoints:
    """Points on the road surface (global metres) and where they came from."""

    xyz: np.ndarray
    """(N, 3)."""
    strip_count: int
    sfm_count: int


def ego_poses(views: list[CameraView]) -> np.ndarray:
    """(K, 4, 4) world_from_ego of each keyframe (one per scene and frame, the first camera's)."""
    seen: dict[tuple[str, int], np.ndarray] = {}
    for view in views:
        seen.setdefault((view.scene, view.frame_index), view.world_from_ego)
    return np.stack(list(seen.values())) if seen else np.zeros((0, 4, 4))


def trajectory_strip(poses: np.ndarray, config: SurfaceConfig) -> np.ndarray:
    """(K * S, 3) samples of the ego z = 0 plane under each pose, global metres."""
    xs = np.arange(config.strip_x_range_m[0], config.strip_x_range_m[1] + 1e-9, config.strip_spacing_m)
    half = config.strip_half_width_m
    ys = np.arange(-half, half + 1e-9, config.strip_spacing_m)
    gx, gy = np.meshgrid(xs, ys, indexing="ij")
    local = np.stack([gx.ravel(), gy.ravel(), np.zeros(gx.size), np.ones(gx.size)], axis=1)
    return np.einsum("kij,sj->ksi", poses, local)[..., :3].reshape(-1, 3)


def sfm_surface_points(workspace: Workspace, site_id: str, config: SurfaceConfig) -> np.ndarray:
    """(M, 3) SfM points labelled road, marking or crosswalk with a small reprojection error; empty
    without SfM."""
    path = workspace.sfm_points(site_id)
    if not config.use_sfm_points or not path.is_file():
        return np.zeros((0, 3))
    points = read_points(path)
    keep = np.isin(points.label, ROAD_SURFACE_IDS) & (points.error_px <= config.sfm_max_error_px)
    return np.asarray(points.xyz[keep], dtype=np.float64)


def surface_points(views: list[CameraView], sfm_xyz: np.ndarray, config: SurfaceConfig) -> SurfacePoints:
    """The strip under the trajectory plus SfM surface points; NoRoadPointsError when both are empty."""
    poses = ego_poses(views)
    strip = (
        trajectory_strip(poses, config) if config.use_trajectory_strip and len(poses) else np.zeros((0, 3))
    )
    if not len(sfm_xyz):
        logger.info(
            "no SfM road points: the surface starts from the %d-point trajectory strip alone", len(strip)
        )
    xyz = np.concatenate([strip, sfm_xyz], axis=0)
    if not len(xyz):
        raise NoRoadPointsError(
            f"no road surface points: {len(poses)} keyframe poses, {len(sfm_xyz)} SfM road points"
        )
    return SurfacePoints(xyz, len(strip), len(sfm_xyz))
