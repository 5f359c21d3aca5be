"""Lift 2D map vectors to 3D through the BEV elevation raster, flagging what cannot be lifted honestly.

A polyline is densified (<= 0.5 m between points by default) and each vertex takes the bilinear interpolation of
the four cells around it (exact on a plane). An unobserved cell (NaN elevation, or marked in the `unobserved`
mask) takes the elevation of the nearest observed cell within `search_radius_m` of it (cell centre to cell
centre); if there is none, the vertex is flagged: its z is NaN and the report names it. Nothing is invented.
"""

import logging
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from annotations.geometry import densify, validate_geometry
from annotations.schema import Georeference, MapElement
from annotations.transforms import pixel_from_site_points
from cama_pipeline.semantics import Semantic

logger = logging.getLogger(__name__)

DEFAULT_MAX_SPACING_M = 0.5
DEFAULT_SEARCH_RADIUS_M = 1.0
_CANDIDATES_PER_CHUNK = 2_000_000
"""Bound on (unobserved cells x neighbourhood offsets) examined at once, to keep memory small."""
_REPORT_LIMIT = 10


class LiftError(ValueError):
    """An element could not be lifted: some vertices have no observed elevation within the search radius."""

    def __init__(self, element_id: str, flagged: tuple[int, ...], report: str) -> None:
        super().__init__(f"element {element_id!r}: cannot lift {len(flagged)} vertices: {report}")
        self.element_id = element_id
        self.flagged = flagged
        self.report = report


@dataclass(frozen=True)
class LiftResult:
    """Lifted points (N, 3) in site metres with z from the raster (NaN where flagged), and what happened."""

    points_3d: np.ndarray
    flagged: tuple[int, ...]
    """Indices into `points_3d` of vertices with no observed elevation within the radius (z is NaN)."""
    filled: tuple[int, ...]
    """Indices of vertices whose z used at least one unobserved cell filled from its nearest observed cell."""
    report: str

    @property
    def ok(self) -> bool:
        """Whether every vertex was lifted."""
        return not self.flagged


class _Raster:
    """The elevation raster with its observed mask, read only at the cells asked for."""

    def __init__(self, elevation: np.ndarray, unobserved: np.ndarray | None, resolution_m: float) -> None:
        self.elevation = elevation
        self.unobserved = unobserved
        self.resolution_m = resolution_m

    def observed(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """True where (row, col) is inside the raster, has a finite elevation and is not marked unobserved."""
        height, width = self.elevation.shape
        inside = (rows >= 0) & (rows < height) & (cols >= 0) & (cols < width)
        r, c = np.where(inside, rows, 0), np.where(inside, cols, 0)
        ok = inside & np.isfinite(self.elevation[r, c])
        if self.unobserved is not None:
            ok &= ~self.unobserved[r, c]
        return ok

    def values(self, rows: np.ndarray, cols: np.ndarray, search_radius_m: float) -> np.ndarray:
        """Elevation at each cell; unobserved cells use the nearest observed cell within the radius, else NaN."""
        out = np.full(rows.shape, np.nan)
        good = self.observed(rows, cols)
        out[good] = self.elevation[rows[good], cols[good]]
        missing = np.flatnonzero(~good)
        offsets = self._offsets(search_radius_m)
        chunk = max(1, _CANDIDATES_PER_CHUNK // len(offsets))
        for start in range(0, len(missing), chunk):
            index = missing[start : start + chunk]
            cand_r = rows[index, None] + offsets[None, :, 0]
            cand_c = cols[index, None] + offsets[None, :, 1]
            ok = self.observed(cand_r, cand_c)
            first = np.argmax(ok, axis=1)  # offsets are sorted nearest first
            found = ok[np.arange(len(index)), first]
            rr, cc = cand_r[found, first[found]], cand_c[found, first[found]]
            out[index[found]] = self.elevation[rr, cc]
        return out

    def _offsets(self, search_radius_m: float) -> np.ndarray:
        """(dr, dc) cell offsets within the radius, nearest first, ties in row-major order."""
        k = int(np.floor(search_radius_m / self.resolution_m + 1e-9))
        dr, dc = np.mgrid[-k : k + 1, -k : k + 1]
        dr, dc = dr.ravel(), dc.ravel()
        distance = self.resolution_m * np.hypot(dr, dc)
        keep = distance <= search_radius_m + 1e-9
        order = np.argsort(distance[keep], kind="stable")
        return np.stack([dr[keep][order], dc[keep][order]], axis=1)


def _unobserved_mask(unobserved: np.ndarray | None, shape: tuple[int, int]) -> np.ndarray | None:
    """A boolean mask from a boolean array (True = unobserved) or a semantic raster (255 = unobserved)."""
    if unobserved is None:
        return None
    mask = np.asarray(unobserved)
    if mask.shape != shape:
        raise ValueError(f"unobserved: mask shape {mask.shape} does not match the elevation raster {shape}")
    if mask.dtype == bool:
        return mask
    if np.issubdtype(mask.dtype, np.integer):
        return mask == int(Semantic.UNOBSERVED)
    raise ValueError(
        f"unobserved: expected a boolean mask or an integer semantic raster, got dtype {mask.dtype}"
    )


def _check_inputs(elevation: np.ndarray, georef: Georeference, max_spacing_m: float, radius_m: float) -> None:
    """ValueError naming the argument when the raster or the parameters are unusable."""
    if elevation.ndim != 2 or elevation.shape != georef.shape:
        raise ValueError(
            f"elevation: raster shape {elevation.shape} does not match the georeference (height, width) {georef.shape}"
        )
    if not np.isfinite(max_spacing_m) or max_spacing_m <= 0:
        raise ValueError(f"max_spacing_m: must be a positive number of metres, got {max_spacing_m}")
    if not np.isfinite(radius_m) or radius_m < 0:
        raise ValueError(f"search_radius_m: must be a non-negative number of metres, got {radius_m}")


def lift_points(
    points_2d: ArrayLike,
    elevation: np.ndarray,
    georef: Georeference,
    *,
    unobserved: np.ndarray | None = None,
    max_spacing_m: float = DEFAULT_MAX_SPACING_M,
    search_radius_m: float = DEFAULT_SEARCH_RADIUS_M,
) -> LiftResult:
    """Densify a 2D site polyline and give every vertex a bilinear z from the elevation raster."""
    elevation = np.asarray(elevation)
    _check_inputs(elevation, georef, max_spacing_m, search_radius_m)
    raster = _Raster(elevation, _unobserved_mask(unobserved, georef.shape), georef.resolution)
    given = validate_geometry(points_2d, closed=False, field="points_2d", dims=2)
    xy = densify(given, max_spacing_m)
    z, flagged, filled = _bilinear(raster, pixel_from_site_points(xy, georef), search_radius_m)
    points = np.column_stack([xy, z])
    report = _report(points, flagged, filled, len(given), max_spacing_m, search_radius_m)
    return LiftResult(points, tuple(flagged.tolist()), tuple(filled.tolist()), report)


def _bilinear(
    raster: _Raster, colrow: np.ndarray, search_radius_m: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Bilinear z at fractional (col, row) pixels, with the indices of flagged and of filled vertices."""
    c0, r0 = np.floor(colrow[:, 0]), np.floor(colrow[:, 1])
    fc, fr = colrow[:, 0] - c0, colrow[:, 1] - r0
    corners = ((0, 0, (1 - fr) * (1 - fc)), (0, 1, (1 - fr) * fc), (1, 0, fr * (1 - fc)), (1, 1, fr * fc))
    z = np.zeros(len(colrow))
    flagged = np.zeros(len(colrow), dtype=bool)
    filled = np.zeros(len(colrow), dtype=bool)
    for dr, dc, weight in corners:
        rows, cols = r0.astype(np.int64) + dr, c0.astype(np.int64) + dc
        used = weight > 0  # a cell with zero weight cannot matter, even when unobserved
        values = raster.values(rows[used], cols[used], search_radius_m)
        filled[used] |= ~raster.observed(rows[used], cols[used]) & np.isfinite(values)
        flagged[used] |= ~np.isfinite(values)
        z[used] += weight[used] * np.nan_to_num(values)
    z[flagged] = np.nan
    return z, np.flatnonzero(flagged), np.flatnonzero(filled & ~flagged)


def _report(
    points: np.ndarray,
    flagged: np.ndarray,
    filled: np.ndarray,
    n_input: int,
    spacing_m: float,
    radius_m: float,
) -> str:
    """A one-paragraph human-readable account of the lift, naming flagged vertices and where they are."""
    direct = len(points) - len(flagged) - len(filled)
    text = (
        f"{len(points)} vertices (densified from {n_input} to <= {spacing_m} m spacing): {direct} on observed "
        f"cells, {len(filled)} using the nearest observed cell within {radius_m} m, {len(flagged)} flagged"
    )
    if len(flagged):
        shown = ", ".join(
            f"{i} at site ({points[i, 0]:.2f}, {points[i, 1]:.2f})" for i in flagged[:_REPORT_LIMIT]
        )
        more = f" and {len(flagged) - _REPORT_LIMIT} more" if len(flagged) > _REPORT_LIMIT else ""
        text += f" (no observed cell within {radius_m} m; z left NaN): vertex {shown}{more}"
    return text


def lift_element(
    element: MapElement,
    elevation: np.ndarray,
    georef: Georeference,
    *,
    unobserved: np.ndarray | None = None,
    max_spacing_m: float = DEFAULT_MAX_SPACING_M,
    search_radius_m: float = DEFAULT_SEARCH_RADIUS_M,
    strict: bool = True,
) -> MapElement:
    """The element with `points_3d` set from the raster; LiftError (strict) or no 3D points when some vertex fails.

    Version and timestamps are left unchanged: the 3D points are derived data, not an edit.
    """
    result = lift_points(
        element.points_2d,
        elevation,
        georef,
        unobserved=unobserved,
        max_spacing_m=max_spacing_m,
        search_radius_m=search_radius_m,
    )
    if result.ok:
        return element.with_changes(points_3d=[(x, y, z) for x, y, z in result.points_3d.tolist()])
    if strict:
        raise LiftError(element.id, result.flagged, result.report)
    logger.warning("element %r not lifted, points_3d cleared: %s", element.id, result.report)
    return element.with_changes(points_3d=None)
