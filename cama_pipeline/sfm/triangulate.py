"""Points from known poses: triangulate every verified match (or start from points already known, such as
the merged clips'), retriangulate, and filter points, through COLMAP's incremental mapper on the model's
working database (no incremental registration)."""

import logging
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pycolmap

from cama_pipeline.sfm.config import SfmConfig
from cama_pipeline.sfm.model import GuidedModel

logger = logging.getLogger(__name__)


def triangulator_options(config: SfmConfig) -> pycolmap.IncrementalTriangulatorOptions:
    """COLMAP's triangulator options for these thresholds (two-view tracks kept unless the config forbids)."""
    options = pycolmap.IncrementalTriangulatorOptions()
    options.ignore_two_view_tracks = config.min_track_length > 2
    options.min_angle = config.min_triangulation_angle_deg
    options.complete_max_reproj_error = config.max_reprojection_error_px
    options.merge_max_reproj_error = config.max_reprojection_error_px
    return options


def triangulate_all(model: GuidedModel, config: SfmConfig) -> int:
    """Triangulate the matches of every registered image from the current poses, then complete and merge
    tracks; returns the observations added."""
    options = triangulator_options(config)
    before = model.reconstruction.compute_num_observations()
    for image_id in sorted(model.reconstruction.reg_image_ids()):
        model.mapper.triangulate_image(options, image_id)
    model.mapper.complete_and_merge_tracks(options)
    return int(model.reconstruction.compute_num_observations() - before)


@dataclass(frozen=True, eq=False)
class SeedPoints:
    """Points known before triangulation (a refined clip's, moved into the merged frame)."""

    xyz: np.ndarray
    """(N, 3) positions, global metres."""
    tracks: tuple[np.ndarray, ...]
    """Per point, (L, 2) int (image id, keypoint index) observations; image ids are the site database's."""
    colors: np.ndarray
    """(N, 3) uint8 RGB."""


def seed_points(model: GuidedModel, seeds: Sequence[SeedPoints], config: SfmConfig) -> int:
    """Add known points, keeping their observations in registered images (points left with fewer than two
    are skipped), then complete and merge tracks across the seeds through the matches; returns the
    observations added. Replaces `triangulate_all` when the points were triangulated and refined before."""
    manager, reconstruction = model.mapper.observation_manager, model.reconstruction
    registered = {int(i) for i in reconstruction.reg_image_ids()}
    before = reconstruction.compute_num_observations()
    for seed in seeds:
        for xyz, observations, color in zip(seed.xyz, seed.tracks, seed.colors, strict=True):
            kept = [(int(i), int(k)) for i, k in observations if int(i) in registered]
            if len(kept) < 2:
                continue
            track = pycolmap.Track()
            for image_id, keypoint in kept:
                track.add_element(image_id, keypoint)
            manager.add_point3D(xyz, track, color)
    model.mapper.complete_and_merge_tracks(triangulator_options(config))
    return int(reconstruction.compute_num_observations() - before)


def model_seeds(reconstruction: pycolmap.Reconstruction, world_from_model: np.ndarray) -> SeedPoints:
    """A model's points and tracks as seeds, moved by a (4, 4) similarity."""
    points = list(reconstruction.points3D.values())
    xyz = np.array([p.xyz for p in points]).reshape(-1, 3)
    tracks = tuple(
        np.array([(e.image_id, e.point2D_idx) for e in p.track.elements], dtype=np.int64).reshape(-1, 2)
        for p in points
    )
    colors = np.array([p.color for p in points], dtype=np.uint8).reshape(-1, 3)
    moved = xyz @ world_from_model[:3, :3].T + world_from_model[:3, 3]
    return SeedPoints(moved, tracks, colors)


def retriangulate(model: GuidedModel, config: SfmConfig) -> int:
    """Retriangulate pairs whose matches lack common points, then complete and merge tracks; returns the
    observations this added or merged."""
    options = triangulator_options(config)
    changed = model.mapper.retriangulate(options)
    changed += model.mapper.complete_and_merge_tracks(options)
    return int(changed)


def filter_points(model: GuidedModel, config: SfmConfig) -> int:
    """Drop points by reprojection error, triangulation angle and track length; returns the observations
    removed."""
    manager = model.mapper.observation_manager
    removed = manager.filter_all_points3D(
        config.max_reprojection_error_px, config.min_triangulation_angle_deg
    )
    removed += manager.filter_points3D_with_short_tracks(config.min_track_length)
    return int(removed)


def image_reprojection_errors(reconstruction: pycolmap.Reconstruction) -> dict[int, tuple[float, int]]:
    """Mean reprojection error (px) and observation count of every registered image with observations."""
    points = reconstruction.points3D
    errors: dict[int, tuple[float, int]] = {}
    for image_id in reconstruction.reg_image_ids():
        image = reconstruction.image(image_id)
        observed = image.get_observation_points2D()
        if not observed:
            continue
        xy = np.array([p.xy for p in observed])
        world = np.array([points[p.point3D_id].xyz for p in observed])
        cam_from_world = image.cam_from_world().matrix()
        in_cam = world @ cam_from_world[:, :3].T + cam_from_world[:, 3]
        projected = reconstruction.camera(image.camera_id).img_from_cam(in_cam, check_cheirality=False)
        residual = np.linalg.norm(projected - xy, axis=1)
        errors[image_id] = (
            float(np.nanmean(np.where(np.isfinite(residual), residual, np.nan))),
            len(observed),
        )
    return errors
