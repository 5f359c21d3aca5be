"""Ground footprints: the part of the ground plane a camera sees, through the image-to-ground homography.

The ground is the ego frame's z = 0 plane (nuScenes puts the ego origin on the ground), so a camera's
footprint follows from its extrinsics alone, as the paper's approximate camera-to-ground relation; the
fused ego pose then places it in the global frame.
"""

import numpy as np
import shapely
from shapely import MultiPoint, Point, Polygon

from cama_pipeline.cameras import CameraView

EMPTY = Polygon()


def ground_hits_ego(view: CameraView, grid: tuple[int, int], max_range_m: float) -> np.ndarray:
    """(N, 2) ego-frame ground points within `max_range_m` of the camera that the camera sees.

    The ground around the camera is sampled on a polar grid (`grid` = ranges, azimuths) and projected into the
    image: a grid in pixels would waste samples on the sky and miss the far road near the horizon."""
    n_ranges, n_azimuths = grid
    origin = view.ego_from_cam[:3, 3]
    ranges = np.linspace(max_range_m / n_ranges, max_range_m, n_ranges)
    azimuths = np.linspace(-np.pi, np.pi, n_azimuths, endpoint=False)
    r, a = np.meshgrid(ranges, azimuths)
    ground = np.stack(
        [origin[0] + r.ravel() * np.cos(a.ravel()), origin[1] + r.ravel() * np.sin(a.ravel())], 1
    )
    cam_from_ego = np.linalg.inv(view.ego_from_cam)
    local = (cam_from_ego[:3, :3] @ np.c_[ground, np.zeros(len(ground))].T).T + cam_from_ego[:3, 3]
    in_front = local[:, 2] > 1e-6
    uv = (view.intrinsic @ (local[in_front] / local[in_front, 2:3]).T).T
    inside = (uv[:, 0] >= 0) & (uv[:, 0] < view.width) & (uv[:, 1] >= 0) & (uv[:, 1] < view.height)
    return np.asarray(ground[in_front][inside])


def ground_footprint(view: CameraView, grid: tuple[int, int], max_range_m: float) -> Polygon:
    """The camera's ground footprint in global x, y: the convex hull of its ground hits within range,
    clipped to the range disk (the image region below the horizon maps to a convex ground region)."""
    hits = ground_hits_ego(view, grid, max_range_m)
    if len(hits) < 3:
        return EMPTY
    world = (view.world_from_ego[:2, :2] @ hits.T).T + view.world_from_ego[:2, 3]
    hull = MultiPoint(world).convex_hull
    if not isinstance(hull, Polygon):
        return EMPTY
    centre = view.center
    return hull.intersection(Point(centre[0], centre[1]).buffer(max_range_m))


def footprint_overlap(a: Polygon | np.ndarray, b: Polygon | np.ndarray) -> np.ndarray:
    """Mutual overlap of footprints: the shared area as a share of the larger one, so both cameras see that much
    of each other's ground (0 when both are empty). Takes two polygons or two arrays of them (vectorised)."""
    larger = np.maximum(shapely.area(a), shapely.area(b))
    shared = shapely.area(shapely.intersection(a, b))
    return np.asarray(np.where(larger > 0, shared / np.where(larger > 0, larger, 1.0), 0.0))
