"""The frame of one map of CAMA's public release: a square of side S metres at r metres per pixel, centred on the
odometry's world origin (CAMA's convention, from its code and release).

world = global - `origin_global` (x and y; the origin's z is 0, so z stays global and the elevation raster holds
global z, as the odometry does). A label point is [u, v] with u = (world y + S/2) / r (the column) and
v = (world x + S/2) / r (the row); the elevation raster is indexed [v, u], so its rows grow with +x and its columns
with +y, pixel centres at integer u, v. Our rasters' columns grow with +x and rows with -y (DESIGN.md), so a
release raster `R` is our-convention raster `our_view(R)` = R.T[::-1] under `our_georeference`.

The origin (`ReleaseFrame.around`): the mean of the camera positions it must cover (a scene's in clip mode, every
scene of the site in site mode, so all scenes of a site share one frame), x and y rounded to 0.1 m.
"""

from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike
from shapely.geometry import Polygon, box

from annotations.schema import Georeference

CamaMode = Literal["clip", "site"]
CAMA_MODES: tuple[CamaMode, ...] = ("clip", "site")
MAP_SIDE_M: dict[CamaMode, float] = {"clip": 300.0, "site": 600.0}
"""Map side per mode: clip 300 m (3000 x 3000 cells), site 600 m (6000 x 6000)."""
ODOMETRY_PREFIX: dict[CamaMode, str] = {"clip": "scmv", "site": "mcmv"}
"""Odometry file prefix per mode: single-clip (scmv) or multi-clip (mcmv) reconstruction."""
RELEASE_RESOLUTION_M = 0.1
"""Metres per map pixel in the public release."""
ORIGIN_ROUNDING_DECIMALS = 1
"""The world origin's x and y are rounded to this many decimals of a metre (0.1 m)."""


@dataclass(frozen=True)
class ReleaseFrame:
    """One release map's frame: world origin (global metres), side and resolution."""

    origin_global: tuple[float, float, float]
    """Global metres of the world origin (the map centre); z is 0 in the maps we write (z stays global)."""
    side_m: float
    """Side S of the square map, metres."""
    resolution_m: float = RELEASE_RESOLUTION_M
    """Metres per pixel."""

    def __post_init__(self) -> None:
        if len(self.origin_global) != 3 or not np.isfinite(self.origin_global).all():
            raise ValueError(f"origin_global: expected 3 finite numbers, got {self.origin_global}")
        for name in ("side_m", "resolution_m"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"{name}: expected a finite value > 0, got {value}")
        if abs(self.side_m / self.resolution_m - self.cells) > 1e-6:
            raise ValueError(f"side_m: {self.side_m} is not a whole number of {self.resolution_m} m pixels")

    @classmethod
    def around(cls, positions_global: ArrayLike, side_m: float) -> "ReleaseFrame":
        """The frame centred on the mean of (N, 2+) global positions, x and y rounded to 0.1 m, z 0."""
        xy = np.asarray(positions_global, dtype=float)
        if xy.ndim != 2 or xy.shape[1] < 2 or len(xy) == 0 or not np.isfinite(xy[:, :2]).all():
            raise ValueError(
                f"positions_global: expected finite (N >= 1, 2+) positions, got shape {xy.shape}"
            )
        mean = xy[:, :2].mean(axis=0)
        origin = (
            round(float(mean[0]), ORIGIN_ROUNDING_DECIMALS),
            round(float(mean[1]), ORIGIN_ROUNDING_DECIMALS),
        )
        return cls((origin[0], origin[1], 0.0), side_m)

    @property
    def cells(self) -> int:
        """Pixels per side."""
        return int(round(self.side_m / self.resolution_m))

    @property
    def origin_xy(self) -> np.ndarray:
        """The world origin's global x, y."""
        return np.asarray(self.origin_global[:2], dtype=float)

    def uv_from_global(self, points: ArrayLike) -> np.ndarray:
        """Global (N, 2+) points (z ignored) to map pixels [u, v] (fractional)."""
        world = _xy(points) - self.origin_xy
        half = self.side_m / 2
        return np.column_stack([(world[:, 1] + half), (world[:, 0] + half)]) / self.resolution_m

    def global_from_uv(self, uv: ArrayLike) -> np.ndarray:
        """Map pixels [u, v] (N, 2) to global x, y."""
        pixels = _xy(uv)
        half = self.side_m / 2
        world = np.column_stack([pixels[:, 1], pixels[:, 0]]) * self.resolution_m - half
        return world + self.origin_xy

    def world_from_global(self, translation: ArrayLike) -> np.ndarray:
        """A global position (3,) in the world frame of the odometry."""
        return np.asarray(translation, dtype=float) - np.asarray(self.origin_global, dtype=float)

    def square_global(self) -> Polygon:
        """The map's pixel-centre square (u, v in [0, cells - 1]) in global x, y."""
        low = self.origin_xy - self.side_m / 2
        high = low + (self.cells - 1) * self.resolution_m
        return box(low[0], low[1], high[0], high[1])

    def our_georeference(self, site_origin_xy: tuple[float, float]) -> Georeference:
        """The georeference (our convention) of `our_view` of this map's raster, at the given site origin."""
        shape = (self.cells, self.cells)
        return release_georeference(
            shape, self.resolution_m, origin_xy=self.origin_xy, site_origin_xy=site_origin_xy
        )


def release_georeference(
    shape: tuple[int, ...],
    resolution_m: float,
    *,
    origin_xy: ArrayLike = (0.0, 0.0),
    site_origin_xy: tuple[float, float] = (0.0, 0.0),
) -> Georeference:
    """The georeference (our convention) of `our_view(R)` for a release raster R of `shape` = (rows, cols)
    centred on `origin_xy` (global metres): x = origin x + v r - rows r / 2, y = origin y + u r - cols r / 2."""
    if not (np.isfinite(resolution_m) and resolution_m > 0):
        raise ValueError(f"resolution_m: expected a finite value > 0, got {resolution_m}")
    rows, cols = int(shape[0]), int(shape[1])
    x0, y0 = (float(value) for value in np.asarray(origin_xy, dtype=float))
    return Georeference(
        site_origin_xy=site_origin_xy,
        origin_xy=(x0 - rows * resolution_m / 2, y0 + (cols / 2 - 1) * resolution_m),
        resolution=resolution_m,
        width=rows,
        height=cols,
    )


def our_view(release: np.ndarray) -> np.ndarray:
    """A release raster indexed [v, u] seen in our convention (rows -y, columns +x): a view, no copy."""
    return release.T[::-1]


def our_pixels_from_uv(uv: ArrayLike, shape: tuple[int, ...]) -> np.ndarray:
    """Release pixels [u, v] of a raster of `shape` = (rows, cols) as pixels (col, row) of `our_view` of it."""
    pixels = _xy(uv)
    return np.column_stack([pixels[:, 1], (int(shape[1]) - 1) - pixels[:, 0]])


def _xy(points: ArrayLike) -> np.ndarray:
    """(N, 2+) float points' first two columns; ValueError on any other shape."""
    array = np.asarray(points, dtype=float)
    if array.ndim != 2 or array.shape[1] < 2:
        raise ValueError(f"points: expected an (N, 2) or (N, 3) array, got shape {array.shape}")
    return array[:, :2]
