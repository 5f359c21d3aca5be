"""The `cama` SRE protocol for one frame: CAMA's crop, projection, skeleton normals and matching.

The rules and constants are described in cama_pipeline/evaluate/sre_cama_config.py. This module holds the per-frame
and per-image steps; cama_pipeline/evaluate/sre_dataset.py runs them over a data set.
"""

import logging
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np
from scipy.optimize import linear_sum_assignment

from cama_pipeline.data import CameraImage, Pose
from cama_pipeline.evaluate.inputs import VectorElement
from cama_pipeline.evaluate.projection import densify
from cama_pipeline.evaluate.sre import ImageInstance, ImageMatch, MatchedPair, SreConfig, extract_instances
from cama_pipeline.evaluate.sre_cama_config import CamaProtocolConfig
from cama_pipeline.evaluate.sre_cama_geometry import normal_distances, pixel_polyline, spline_normals
from cama_pipeline.evaluate.sre_report import ImageSre

logger = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class DenseMap:
    """The scored map elements densified once, all points in one array."""

    ids: tuple[str, ...]
    """Element ids, indexed by `owner`."""
    points: np.ndarray
    """(N, 3) global metres; z is NaN for points of 2D elements (given the frame's ego height)."""
    owner: np.ndarray
    """(N,) index into `ids` of each point, points of an element contiguous and in order."""


@dataclass(frozen=True, eq=False)
class CamaProjection:
    """One map element as CAMA's code sees it in one image."""

    element_id: str
    polyline_px: np.ndarray
    """(M, 2) [u, v] at the protocol's image size: distinct integer pixels in (row, column) order."""


def densify_map(elements: Sequence[VectorElement], config: CamaProtocolConfig) -> DenseMap:
    """Densify every element to `config.densify_m` (2D elements get NaN heights)."""
    arrays, owners = [], []
    for index, element in enumerate(elements):
        dense = densify(element.points, config.densify_m, closed=element.closed)
        if not element.has_elevation:
            dense = np.column_stack([dense, np.full(len(dense), np.nan)])
        arrays.append(dense)
        owners.append(np.full(len(dense), index, np.int64))
    if not arrays:
        return DenseMap((), np.zeros((0, 3)), np.zeros(0, np.int64))
    return DenseMap(tuple(e.id for e in elements), np.vstack(arrays), np.concatenate(owners))


def crop_to_ego(
    dense: DenseMap, global_from_ego: Pose, config: CamaProtocolConfig
) -> tuple[np.ndarray, np.ndarray]:
    """Points in the ego (chassis) frame inside the crop box, and their owners."""
    points = dense.points
    if np.isnan(points[:, 2]).any():
        points = points.copy()
        points[np.isnan(points[:, 2]), 2] = global_from_ego.translation[2]
    ego = global_from_ego.inverse().transform_points(points)
    keep = np.ones(len(ego), bool)
    for axis, (low, high) in enumerate((config.crop_x_m, config.crop_y_m, config.crop_z_m)):
        keep &= (ego[:, axis] >= low) & (ego[:, axis] <= high)
    return ego[keep], dense.owner[keep]


def scaled_intrinsic(image: CameraImage, config: CamaProtocolConfig) -> np.ndarray:
    """The pinhole matrix of the image resampled to the protocol's size (rows scaled as CAMA does)."""
    intrinsic = np.array(image.calibration.intrinsic, dtype=np.float64)
    intrinsic[0] *= config.image_width_px / image.calibration.width
    intrinsic[1] *= config.image_height_px / image.calibration.height
    return intrinsic


def resample_mask(mask: np.ndarray, image: CameraImage, config: CamaProtocolConfig) -> np.ndarray:
    """The instance mask resampled to the protocol's size, nearest neighbour through the scaled pinhole
    matrix (CAMA's undistort-and-resize remap; the data set's cameras have no distortion)."""
    size = (config.image_width_px, config.image_height_px)
    map_u, map_v = cv2.initUndistortRectifyMap(
        np.array(image.calibration.intrinsic, dtype=np.float64),
        np.zeros(5),
        None,
        scaled_intrinsic(image, config),
        size,
        cv2.CV_32FC1,
    )
    return cv2.remap(mask, map_u, map_v, interpolation=cv2.INTER_NEAREST)


def project_camera(
    ego_points: np.ndarray,
    owner: np.ndarray,
    ids: Sequence[str],
    image: CameraImage,
    config: CamaProtocolConfig,
) -> list[CamaProjection]:
    """Every element seen by the camera with at least `min_points` distinct pixels."""
    cam = image.calibration.ego_from_cam.inverse().transform_points(ego_points)
    front = cam[:, 2] > 0
    cam, owner = cam[front], owner[front]
    uvw = cam @ scaled_intrinsic(image, config).T
    uv = uvw[:, :2] / uvw[:, 2:3]
    out = []
    for index in np.unique(owner):
        points = uv[owner == index]
        pixels = pixel_polyline(points, config.image_width_px, config.image_height_px)
        if len(pixels) < config.min_points:
            continue
        if not config.pixel_polyline:
            pixels = _ordered_inside(points, config)
        out.append(CamaProjection(ids[index], pixels))
    return out


def match_cama(
    projections: Sequence[CamaProjection], instances: Sequence[ImageInstance], config: CamaProtocolConfig
) -> ImageMatch:
    """CAMA's Hungarian matching of one image: cost = mean normal distance, 500 where no normal crosses."""
    if not projections or not instances:
        return ImageMatch(len(projections), len(instances), ())
    cost = np.full((len(instances), len(projections)), config.no_crossing_cost)
    for row, instance in enumerate(instances):
        normals = spline_normals(instance.skeleton_px, config)
        if normals is None:
            continue
        for col, projection in enumerate(projections):
            distances = normal_distances(*normals, config.search_px, projection.polyline_px)
            if distances.size:
                cost[row, col] = float(distances.mean())
    pairs = [
        MatchedPair(projections[c].element_id, instances[r].value, float(cost[r, c]))
        for r, c in zip(*linear_sum_assignment(cost), strict=True)
        if cost[r, c] < config.match_below
    ]
    return ImageMatch(len(projections), len(instances), tuple(pairs))


def evaluate_frame(
    scene: str,
    frame: str,
    images: Sequence[CameraImage],
    global_from_ego: Pose | Sequence[Pose],
    dense: DenseMap,
    config: SreConfig,
) -> list[ImageSre]:
    """Score the images of one frame: through one ego pose (CAMA: the front camera's) or one pose per image."""
    cama = config.cama
    poses = [global_from_ego] * len(images) if isinstance(global_from_ego, Pose) else list(global_from_ego)
    shared = crop_to_ego(dense, global_from_ego, cama) if isinstance(global_from_ego, Pose) else None
    mask_classes = {int(m) for _, m in config.class_pairs}
    out = []
    for image, pose in zip(images, poses, strict=True):
        ego_points, owner = shared if shared is not None else crop_to_ego(dense, pose, cama)
        projections = project_camera(ego_points, owner, dense.ids, image, cama)
        mask = resample_mask(image.load_instance(), image, cama)
        instances = extract_instances(mask, mask_classes, cama.min_points)
        match = match_cama(projections, instances, cama)
        out.append(
            ImageSre(
                scene,
                frame,
                image.channel,
                image.token,
                cama.image_width_px,
                match,
                config.reference_width_px,
                require_match=True,
            )
        )
    return out


def _ordered_inside(points_uv: np.ndarray, config: CamaProtocolConfig) -> np.ndarray:
    """The projected points inside the image in their order along the element (the diagnostic variant)."""
    u, v = points_uv[:, 0], points_uv[:, 1]
    inside = (u >= 0) & (u < config.image_width_px) & (v >= 0) & (v < config.image_height_px)
    return points_uv[inside]
