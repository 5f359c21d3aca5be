"""The elevation raster of a release map (`vision_road_mlp_ft.npy`): our elevation raster resampled onto the map's
grid (float32, indexed [v, u], see `annotations.cama_frame`), with no NaN.

Resampling: each map cell takes the bilinear interpolation of the four cells of our raster around its centre
(exact on a plane), or, where one of those is unobserved (NaN) or outside our raster, the nearest cell's value.
Cells still without a value are filled from the nearest observed map cell (`scipy.ndimage.distance_transform_edt`
indices) inside the bounding box of the observed cells; cells outside that box take the value of the nearest
cell of the box (the EDT's index arrays of a whole 6000 x 6000 map would take 288 MB). Which cells were filled is
returned (and written beside the sidecar as `elevation_filled.png`: 255 filled, 0 observed, [v, u]). A map
without any observed cell is refused. Without a raster, a map may be the mean z of the lifted elements, every
cell marked filled (`constant_elevation`).
"""

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.ndimage import distance_transform_edt

from annotations.cama_frame import ReleaseFrame
from annotations.cama_sidecar import ElevationSource
from cama_pipeline.bev import RasterGeoreference
from cama_pipeline.io import atomic_write_image, atomic_write_npy

ELEVATION_NPY = "vision_road_mlp_ft.npy"
FILLED_PNG = "elevation_filled.png"
_CHUNK = 256
"""Map rows resampled at once (bounds the temporaries to a few MB at 6000 cells a row)."""


@dataclass(frozen=True, eq=False)
class ReleaseElevation:
    """A release map's elevation (cells x cells float32, no NaN) and which cells were filled."""

    values: np.ndarray
    filled: np.ndarray
    """Boolean, True where the value was filled rather than observed."""
    source: ElevationSource

    @property
    def filled_cells(self) -> int:
        """How many cells were filled."""
        return int(self.filled.sum())

    def write(self, npy_path: Path, filled_png_path: Path) -> None:
        """The raster as .npy and the filled mask as an 8-bit PNG (255 filled), each atomically."""
        atomic_write_npy(npy_path, self.values)
        atomic_write_image(filled_png_path, self.filled.astype(np.uint8) * np.uint8(255))


def release_elevation(
    elevation: np.ndarray, georef: RasterGeoreference, frame: ReleaseFrame, *, where: str
) -> ReleaseElevation:
    """Our (H, W) raster (global z, NaN unobserved) on the map's grid, filled; ValueError naming `where` when no
    map cell is observed."""
    values = _resample(np.asarray(elevation), georef, frame)
    observed = np.isfinite(values)
    if not observed.any():
        raise ValueError(
            f"{where}: no observed elevation cell within the {frame.side_m:g} m map centred at global "
            f"{frame.origin_global[:2]}: the elevation raster does not cover it"
        )
    filled = ~observed
    del observed
    if filled.any():
        _fill_nearest(values, filled)
    return ReleaseElevation(values, filled, "raster")


def constant_elevation(z: float, frame: ReleaseFrame) -> ReleaseElevation:
    """A map of one height (every cell filled): for an export without an elevation raster."""
    if not np.isfinite(z):
        raise ValueError(f"z: expected a finite height, got {z}")
    shape = (frame.cells, frame.cells)
    return ReleaseElevation(np.full(shape, z, dtype=np.float32), np.ones(shape, dtype=bool), "elements-mean")


def _resample(elevation: np.ndarray, georef: RasterGeoreference, frame: ReleaseFrame) -> np.ndarray:
    """Map cells [v, u] sampled from our raster (bilinear, else nearest, else NaN), float32."""
    steps = np.arange(frame.cells) * frame.resolution_m - frame.side_m / 2
    cols = (frame.origin_xy[0] + steps - georef.origin_xy[0]) / georef.resolution  # per v
    rows = (georef.origin_xy[1] - (frame.origin_xy[1] + steps)) / georef.resolution  # per u
    out = np.full((frame.cells, frame.cells), np.nan, dtype=np.float32)
    v_near = np.flatnonzero((cols > -1) & (cols < georef.width))  # map rows that can touch our raster
    u_near = np.flatnonzero((rows > -1) & (rows < georef.height))
    if not (v_near.size and u_near.size):
        return out
    u0, u1 = int(u_near[0]), int(u_near[-1]) + 1
    for start in range(int(v_near[0]), int(v_near[-1]) + 1, _CHUNK):
        stop = min(start + _CHUNK, int(v_near[-1]) + 1)
        out[start:stop, u0:u1] = _sample(elevation, rows[u0:u1], cols[start:stop]).T  # sampled as (u, v)
    return out


def _sample(elevation: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """Our raster at fractional (rows x cols): bilinear where its four cells are observed, else the nearest."""
    r0, c0 = np.floor(rows), np.floor(cols)
    fr, fc = (rows - r0).astype(np.float32)[:, None], (cols - c0).astype(np.float32)[None, :]
    r0i, c0i = r0.astype(np.int64), c0.astype(np.int64)
    bilinear = (
        _gather(elevation, r0i, c0i) * (1 - fr) * (1 - fc)
        + _gather(elevation, r0i, c0i + 1) * (1 - fr) * fc
        + _gather(elevation, r0i + 1, c0i) * fr * (1 - fc)
        + _gather(elevation, r0i + 1, c0i + 1) * fr * fc
    )
    nearest = _gather(elevation, np.rint(rows).astype(np.int64), np.rint(cols).astype(np.int64))
    return np.where(np.isfinite(bilinear), bilinear, nearest)


def _gather(elevation: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """elevation[rows x cols] as float32 (the map's type), NaN where a row or column is outside the raster."""
    height, width = elevation.shape
    block = elevation[np.ix_(np.clip(rows, 0, height - 1), np.clip(cols, 0, width - 1))].astype(np.float32)
    block[(rows < 0) | (rows >= height), :] = np.nan
    block[:, (cols < 0) | (cols >= width)] = np.nan
    return block


def _fill_nearest(values: np.ndarray, filled: np.ndarray) -> None:
    """Fill the `filled` cells of `values` in place: nearest observed cell inside the observed cells' bounding
    box, then the nearest cell of that box outside it."""
    observed_rows = np.flatnonzero(~filled.all(axis=1))
    observed_cols = np.flatnonzero(~filled.all(axis=0))
    v0, v1 = int(observed_rows[0]), int(observed_rows[-1]) + 1
    u0, u1 = int(observed_cols[0]), int(observed_cols[-1]) + 1
    crop = values[v0:v1, u0:u1]
    holes = filled[v0:v1, u0:u1]
    if holes.any():
        iv, iu = distance_transform_edt(holes, return_distances=False, return_indices=True)
        crop[...] = crop[iv, iu]
        del iv, iu
    values[:v0, u0:u1] = values[v0, u0:u1]
    values[v1:, u0:u1] = values[v1 - 1, u0:u1]
    values[:, :u0] = values[:, u0 : u0 + 1]
    values[:, u1:] = values[:, u1 - 1 : u1]
