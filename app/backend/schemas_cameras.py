"""Response shapes of the camera panel's endpoints (pydantic): status, views, camera parameters, projections."""

import logging
from typing import Literal

from pydantic import BaseModel, Field

logger = logging.getLogger(__name__)

Pixel = list[float]
"""[u, v]: full-resolution image pixels (u = column, v = row, pixel centres at integers)."""


class CamerasStatus(BaseModel):
    """Whether a site's camera panel can show anything, and if not why."""

    available: bool = Field(
        description="Whether some key-frame image has an SfM pose (views can be offered)."
    )
    notice: str | None = Field(description="Why nothing can be shown (null when views are available).")
    images: int = Field(description="Key-frame camera images (of the reconstruction's scenes when known).")
    posed: int = Field(description="Key-frame camera images with an SfM pose: the ones offered as views.")
    mask_source: Literal["dataset", "predicted", "imported"] | None = Field(
        description="Where the lane-mask overlays come from; null when there are none."
    )


class ViewPublic(BaseModel):
    """One key-frame image that sees the element (or point), and how well."""

    token: str
    channel: str
    scene: str
    timestamp_us: int
    width: int
    height: int
    score: float = Field(description="0..1: near, central views that see much of the element score high.")
    distance_m: float = Field(description="Camera centre to the nearest part of the element it sees (3D).")
    obliqueness_deg: float = Field(description="Angle between the optical axis and the ray to that part.")
    station_m: float = Field(description="Arc length along the element of that part (0 for a point).")


class ViewsPublic(BaseModel):
    """The views of an element or point, in station order; `notice` says what is missing (no reconstruction,
    no elevation under the element)."""

    notice: str | None
    views: list[ViewPublic]


class CameraPublic(BaseModel):
    """A posed image's pinhole camera in site coordinates: a site point p (global minus the site origin in x
    and y, z global) projects to K @ (R p + t), with [R | t] the top rows of `cam_from_site`."""

    width: int
    height: int
    K: list[list[float]] = Field(description="3x3 pinhole matrix (full-resolution pixels).")
    cam_from_site: list[list[float]] = Field(
        description="4x4 rigid map from site coordinates into the camera frame (x right, y down, z forward)."
    )
    pose_source: str = Field(description="Where the pose came from: sfm, wigo+sfm or wigo.")


class NeighbourPublic(BaseModel):
    """Another live element near the projected one, as it appears in the image."""

    id: int
    cls: str
    pieces: list[list[Pixel]]


class ProjectionPublic(BaseModel):
    """An element lifted to 3D and projected into one image."""

    points_3d: list[list[float]] = Field(description="The lifted element: [x, y, z] site metres, densified.")
    pieces: list[list[Pixel]] = Field(
        description="The parts in front of the camera, clipped to the image (full-resolution pixels)."
    )
    neighbours: list[NeighbourPublic] = Field(
        description="Other live elements within 30 m that project into the image (when asked for)."
    )
    notice: str | None = Field(
        default=None, description="What could not be lifted from the elevation raster."
    )
