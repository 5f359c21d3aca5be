"""An image's camera in site coordinates, and lifted elements projected into it.

The projection itself is `cama_pipeline.evaluate.projection.project_polyline` (densified, cut to the part in
front of the camera and within range, clipped to the image) on the camera `sre_dataset.camera_for` makes of the
image and its refined pose: the panel draws exactly what the SRE evaluates.
"""

import logging
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from app.backend.cameras.context import CameraContext
from app.backend.cameras.views import lift_site_points
from cama_pipeline.evaluate.projection import PinholeCamera, ProjectionConfig, project_polyline
from cama_pipeline.evaluate.sre_dataset import camera_for

logger = logging.getLogger(__name__)

DRAW = ProjectionConfig(range_m=100.0, near_m=0.5, spacing_m=0.5)
"""How the panel's polylines are cut: up to 100 m from the camera (a far part is still drawn; views are chosen
within 40 m), from 0.5 m in front of it."""


class ImageNotFound(LookupError):
    """A token that is not a camera image of the site's data set, or has no pose where one is needed."""


@dataclass(frozen=True)
class ImageCamera:
    """An image's pinhole camera under its refined pose."""

    camera: PinholeCamera
    """Global metres, OpenCV axes."""
    pose_source: str
    """Where the pose came from (`sfm`, `wigo+sfm`, `wigo`)."""


def image_camera(context: CameraContext, token: str) -> ImageCamera:
    """The camera of a camera image with a refined pose; ImageNotFound otherwise."""
    view = context.by_token.get(token)
    if view is not None:
        return ImageCamera(view.camera, view.pose_source)
    refined = context.poses.get(token)
    if context.dataset is None or refined is None:
        raise ImageNotFound("no posed camera image with this token in the site's data set")
    try:
        image = context.dataset.image(token)
    except KeyError:
        raise ImageNotFound("no posed camera image with this token in the site's data set") from None
    return ImageCamera(camera_for(image, refined.global_from_ego), refined.source)


def cam_from_site(camera: PinholeCamera, site_origin_xy: tuple[float, float]) -> np.ndarray:
    """(4, 4) rigid map from site coordinates (global - site origin, z global) into the camera frame (x right,
    y down, z forward): a site point p projects to K @ (R p + t)."""
    rotation = camera.global_from_cam_rotation.T
    centre_site = camera.global_from_cam_translation - np.array([site_origin_xy[0], site_origin_xy[1], 0.0])
    matrix = np.eye(4)
    matrix[:3, :3] = rotation
    matrix[:3, 3] = -rotation @ centre_site
    return matrix


def project_site_polyline(
    context: CameraContext, camera: PinholeCamera, points_3d_site: ArrayLike
) -> list[np.ndarray]:
    """The visible pieces ((M, 2) full-resolution pixels [u, v]) of a 3D site polyline in a camera."""
    points = np.asarray(points_3d_site, dtype=np.float64)
    if len(points) < 2:
        return []
    global_points = points + np.array([context.site_origin_xy[0], context.site_origin_xy[1], 0.0])
    return [piece.points_px for piece in project_polyline(global_points, camera, DRAW)]


@dataclass(frozen=True)
class ProjectedNeighbour:
    """Another element's visible pieces in an image."""

    id: int
    cls: str
    pieces: list[np.ndarray]


def project_neighbours(
    context: CameraContext, camera: PinholeCamera, neighbours: Sequence[tuple[int, str, ArrayLike]]
) -> list[ProjectedNeighbour]:
    """(id, class, 2D site points) elements lifted and projected; those with nothing in view left out."""
    out = []
    for element_id, cls, points in neighbours:
        try:
            lifted = lift_site_points(context, points)
        except ValueError as error:
            logger.info("neighbour %s not projected: %s", element_id, error)
            continue
        pieces = project_site_polyline(context, camera, lifted.points_3d)
        if pieces:
            out.append(ProjectedNeighbour(element_id, cls, pieces))
    return out
