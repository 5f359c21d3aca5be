"""Which key-frame images see an element best: the element lifted through the elevation raster, tested in every
posed view, scored and spread along the element.

Lifting (`lift_site_points`): the 2D site polyline is densified (<= 0.5 m) and each vertex takes the bilinear
elevation (`annotations.lift`; an unobserved cell takes the nearest observed one within 2 m). Vertices still
without a height take it by linear interpolation along the element from the lifted ones; an element with none
lifted (or a site without an elevation raster) is drawn at the ground height of the cameras near it (the median
ego height of the posed views within 40 m), and the result says so in its notice.

Visibility: a view sees a vertex that is in front of it (camera z >= 0.5 m), within 40 m of its centre and
projects inside the image. A candidate sees at least one vertex. Its figures are those of the nearest vertex it
sees: `distance_m`, `obliqueness_deg` (the angle between the optical axis and the ray to it) and `station_m`
(its arc length along the element). Score, in [0, 1]: `(1 - distance / 40 m) * cos(obliqueness) * (0.5 + 0.5 *
share)`, `share` the fraction of the element's vertices it sees: near, central views that see much of it win.

Spread (`best_views`): the n views are picked greedily by score, each candidate's score damped by how close
(in station) it is to those already picked, relative to the element's length / n (down to a quarter at the same
station), so that the chosen views step along the element; they are returned in station order.
"""

import logging
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from annotations.geometry import densify
from annotations.lift import lift_points
from app.backend.cameras.context import CameraContext

logger = logging.getLogger(__name__)

MAX_RANGE_M = 40.0
"""A view sees a vertex at most this far (3D) from its centre."""
NEAR_M = 0.5
"""A view sees a vertex at least this far in front of it (camera z)."""
LIFT_SPACING_M = 0.5
"""Vertex spacing of a lifted element."""
LIFT_SEARCH_RADIUS_M = 2.0
"""An unobserved elevation cell takes the nearest observed one within this distance."""
POINT_STEP_M = 0.01
"""A point is lifted as the start of a segment this long (the lift needs a polyline)."""
SAME_SPOT_M = 1.0
"""Views of one camera taken closer than this to a chosen one add nothing new to the panel."""
SAME_SPOT_FACTOR = 0.05
"""Such a view keeps this share of its score (chosen only when nothing else sees the element)."""
NO_ELEVATION = "no elevation under this element: drawn at the ground height of the cameras near it"
PARTLY_LIFTED = "part of this element has no elevation under it: its height there is interpolated"


@dataclass(frozen=True, eq=False)
class LiftedElement:
    """An element (or a point) in 3D site metres: x, y site (global - site origin), z global."""

    points_3d: np.ndarray
    """(N, 3) densified vertices."""
    station_m: np.ndarray
    """(N,) arc length of each vertex along the element (horizontal metres)."""
    notice: str | None
    """What could not be lifted from the raster, when something could not."""

    def global_points(self, site_origin_xy: tuple[float, float]) -> np.ndarray:
        """(N, 3) global metres."""
        return self.points_3d + np.array([site_origin_xy[0], site_origin_xy[1], 0.0])


@dataclass(frozen=True)
class ViewChoice:
    """One view of an element: which image, and how well it sees the element (see the module docstring)."""

    token: str
    channel: str
    scene: str
    timestamp_us: int
    width: int
    height: int
    score: float
    distance_m: float
    obliqueness_deg: float
    station_m: float
    centre_xy: tuple[float, float] = (0.0, 0.0)
    """The camera's global x, y (to tell views taken from the same spot apart from new viewpoints)."""


def _stations(xy: np.ndarray) -> np.ndarray:
    """Cumulative horizontal arc length of a polyline's vertices."""
    steps = np.linalg.norm(np.diff(xy[:, :2], axis=0), axis=1)
    return np.concatenate([[0.0], np.cumsum(steps)])


def ground_height(context: CameraContext, xy_site: np.ndarray) -> float:
    """The median ego height of the posed views within MAX_RANGE_M of the points (of all views when none is
    near; 0 without views): where the road is under the cameras."""
    if not context.views:
        return 0.0
    ego_z = np.array([view.global_from_ego.translation[2] for view in context.views])
    ego_xy = np.array([view.global_from_ego.translation[:2] for view in context.views])
    points = np.asarray(xy_site, dtype=np.float64)[:, :2] + np.asarray(context.site_origin_xy)
    gaps = np.linalg.norm(ego_xy[:, None, :] - points[None, :, :], axis=2).min(axis=1)
    near = gaps <= MAX_RANGE_M
    return float(np.median(ego_z[near] if near.any() else ego_z))


def _fill_heights(context: CameraContext, xy: np.ndarray, z: np.ndarray) -> tuple[np.ndarray, str | None]:
    """Heights with the unlifted (NaN) ones interpolated along the element, or all at the ground height."""
    lifted = np.isfinite(z)
    if lifted.all():
        return z, None
    if not lifted.any():
        return np.full(len(xy), ground_height(context, xy)), NO_ELEVATION
    stations = _stations(xy)
    return np.interp(stations, stations[lifted], z[lifted]), PARTLY_LIFTED


def lift_site_points(context: CameraContext, points_site_2d: ArrayLike) -> LiftedElement:
    """Lift a 2D site polyline (N >= 2 points, not all coincident) to 3D; ValueError for a bad polyline."""
    points = np.asarray(points_site_2d, dtype=np.float64)
    if points.ndim != 2 or points.shape[0] < 2 or points.shape[1] != 2 or not np.isfinite(points).all():
        raise ValueError(f"points: expected an (N >= 2, 2) finite site polyline, got shape {points.shape}")
    if context.elevation is None:
        xy = densify(points, LIFT_SPACING_M)
        z = np.full(len(xy), np.nan)
    else:
        result = lift_points(
            points,
            context.elevation,
            context.sources.georeference,
            max_spacing_m=LIFT_SPACING_M,
            search_radius_m=LIFT_SEARCH_RADIUS_M,
        )
        xy, z = result.points_3d[:, :2], result.points_3d[:, 2]
    z, notice = _fill_heights(context, xy, z)
    return LiftedElement(np.column_stack([xy, z]), _stations(xy), notice)


def lift_site_point(context: CameraContext, xy_site: tuple[float, float]) -> LiftedElement:
    """Lift one site point (a one-vertex element at station 0)."""
    x, y = float(xy_site[0]), float(xy_site[1])
    lifted = lift_site_points(context, [[x, y], [x + POINT_STEP_M, y]])
    return LiftedElement(lifted.points_3d[:1], np.zeros(1), lifted.notice)


def candidates(context: CameraContext, lifted: LiftedElement) -> list[ViewChoice]:
    """Every posed view that sees part of the lifted element, with its figures (view order)."""
    if not context.views:
        return []
    points = lifted.global_points(context.site_origin_xy)
    low, high = points[:, :2].min(axis=0), points[:, :2].max(axis=0)
    gap = np.linalg.norm(
        np.maximum(0.0, np.maximum(low - context.centres[:, :2], context.centres[:, :2] - high)), axis=1
    )
    near = np.flatnonzero(gap <= MAX_RANGE_M)
    if near.size == 0:
        return []
    rotations, centres = context.rotations[near], context.centres[near]
    cam = (
        np.einsum("nk,skj->snj", points, rotations) - np.einsum("sk,skj->sj", centres, rotations)[:, None, :]
    )
    depth, distance = cam[..., 2], np.linalg.norm(cam, axis=2)
    uvw = np.einsum("snj,sij->sni", cam, context.intrinsics[near])
    with np.errstate(divide="ignore", invalid="ignore"):
        uv = uvw[..., :2] / uvw[..., 2:3]
    size = context.sizes[near][:, None, :]
    inside = ((uv >= -0.5) & (uv <= size - 0.5)).all(axis=2)
    visible = (depth >= NEAR_M) & (distance <= MAX_RANGE_M) & inside
    out = []
    for row in np.flatnonzero(visible.any(axis=1)):
        view = context.views[int(near[row])]
        nearest = int(np.argmin(np.where(visible[row], distance[row], np.inf)))
        d = float(distance[row, nearest])
        cos_angle = float(depth[row, nearest]) / d
        share = float(visible[row].mean())
        score = (1.0 - d / MAX_RANGE_M) * cos_angle * (0.5 + 0.5 * share)
        out.append(
            ViewChoice(
                token=view.token,
                channel=view.channel,
                scene=view.scene,
                timestamp_us=view.timestamp_us,
                width=view.width,
                height=view.height,
                score=round(score, 4),
                distance_m=round(d, 2),
                obliqueness_deg=round(float(np.degrees(np.arccos(min(1.0, cos_angle)))), 2),
                station_m=round(float(lifted.station_m[nearest]), 2),
                centre_xy=(float(centres[row, 0]), float(centres[row, 1])),
            )
        )
    return out


def spread(choices: list[ViewChoice], n: int, length_m: float) -> list[ViewChoice]:
    """The n best choices spread along the element (see the module docstring), in station order."""
    remaining = sorted(choices, key=lambda c: (-c.score, c.token))
    spacing = length_m / n
    chosen: list[ViewChoice] = []
    while remaining and len(chosen) < n:
        best = max(remaining, key=lambda choice: _damped(choice, chosen, spacing))
        chosen.append(best)
        remaining.remove(best)
    return in_station_order(chosen)


def _damped(choice: ViewChoice, chosen: list[ViewChoice], spacing_m: float) -> float:
    """A choice's score damped by its station's nearness to the chosen ones (a quarter at the same station), and
    nearly cancelled when a chosen view of the same camera was taken from the same spot (a parked or slow car's
    frames show the same picture again)."""
    if not chosen:
        return choice.score
    if any(c.channel == choice.channel and _apart_m(c, choice) < SAME_SPOT_M for c in chosen):
        return choice.score * SAME_SPOT_FACTOR
    if spacing_m <= 0.0:
        return choice.score
    gap = min(abs(choice.station_m - c.station_m) for c in chosen)
    return choice.score * (0.25 + 0.75 * min(1.0, gap / spacing_m))


def _apart_m(a: ViewChoice, b: ViewChoice) -> float:
    """Horizontal distance between two views' cameras."""
    return float(np.hypot(a.centre_xy[0] - b.centre_xy[0], a.centre_xy[1] - b.centre_xy[1]))


def in_station_order(choices: list[ViewChoice]) -> list[ViewChoice]:
    """Choices by station, then best score first, then token."""
    return sorted(choices, key=lambda c: (c.station_m, -c.score, c.token))


def select(context: CameraContext, lifted: LiftedElement, n: int, all_: bool = False) -> list[ViewChoice]:
    """The views of a lifted element: the n best spread along it, or every candidate (`all_`), station order."""
    if n < 1:
        raise ValueError(f"n: must be >= 1, got {n}")
    found = candidates(context, lifted)
    if all_:
        return in_station_order(found)
    return spread(found, n, float(lifted.station_m[-1]))


def best_views(
    context: CameraContext, element_points_site_2d: ArrayLike, n: int, all_: bool = False
) -> list[ViewChoice]:
    """The n (>= 1) key-frame views that see an element's 2D site polyline best, spread along it, in station
    order; every view that sees it with `all_`. Empty without a reconstruction. ValueError for a bad
    polyline or n."""
    return select(context, lift_site_points(context, element_points_site_2d), n, all_)


def best_views_for_point(
    context: CameraContext, xy_site: tuple[float, float], n: int, all_: bool = False
) -> list[ViewChoice]:
    """The n (>= 1) key-frame views that see a site point best (by score), or every one with `all_`."""
    return select(context, lift_site_point(context, xy_site), n, all_)
