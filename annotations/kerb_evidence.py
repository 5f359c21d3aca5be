"""Whether each road boundary is a kerb, read from the site's semantic BEV raster (for the Lanelet2 export).

A `boundary` element does not say whether a kerb was seen there or the road just ends; the semantic raster
(`cama_pipeline.semantics` ids, 255 unobserved, in the annotation set's georeference) does. Each boundary is
sampled at stations one raster cell apart along its 2D polyline; at each station the cells across the line,
`BAND_M` to either side (one cell apart, the nearest cell to each sample), are read. A station is observed when
any of its cells is. Per element:

- `unobserved`: fewer than `MIN_OBSERVED_M` metres or `MIN_OBSERVED_FRACTION` of the stations observed, so the
  raster cannot tell (the export keeps the assumed kerb).
- `observed` (a kerb): curb cells in the band at `KERB_MIN_FRACTION` or more of the observed stations.
- `none` (a road border without a kerb): fewer curb stations, and at `EDGE_MIN_FRACTION` or more of the observed
  stations road (road, lane marking or crosswalk) on one side of the line and off-road (background: terrain,
  grass, sidewalk) on the other.
- otherwise `unobserved` too: observed, but not beside a road edge (e.g. a boundary drawn inside the road or in
  the grass), so the raster says neither kerb nor road border; `reason` tells the two apart.

Why these numbers: a kerb is a strip one to three cells wide at 0.1 m (the generator draws 0.15-0.3 m) right at
the boundary, so "any curb cell within +-0.5 m" tolerates a boundary drawn a few decimetres off; the segmenter
finds curb at IoU 0.38 on unseen sites, so a real kerb shows as curb along only part of its length, while a
road end without one gets curb cells only where the segmenter errs (a few percent): 30 % of the observed stations
sits between the two. The road-edge test asks for half the stations, so a boundary that leaves the road edge
for a stretch still counts, but one that lies mostly inside the road does not.
"""

from dataclasses import dataclass
from typing import Literal

import numpy as np

from annotations.geometry import densify
from annotations.schema import AnnotationSet, Georeference, MapElement
from annotations.transforms import pixel_from_site_points
from cama_pipeline.semantics import ROAD_SURFACE_IDS, Semantic

KerbVerdict = Literal["observed", "none", "unobserved"]
KERB_VERDICTS: tuple[KerbVerdict, ...] = ("observed", "none", "unobserved")

BAND_M = 0.5
"""Cells up to this far to either side of the boundary are read at each station."""
MIN_OBSERVED_M = 2.0
"""Fewer observed metres of boundary than this: `unobserved`."""
MIN_OBSERVED_FRACTION = 0.3
"""Fewer observed stations than this fraction of the boundary's: `unobserved` (a short observed stretch does
not speak for the whole element)."""
KERB_MIN_FRACTION = 0.3
"""Curb cells in the band at this fraction of the observed stations or more: a kerb (`observed`)."""
EDGE_MIN_FRACTION = 0.5
"""Road on one side and off-road on the other at this fraction of the observed stations or more (and no kerb):
a road border (`none`)."""

OFF_ROAD_ID = int(Semantic.BACKGROUND)


@dataclass(frozen=True)
class BoundaryEvidence:
    """What the raster says along one boundary."""

    verdict: KerbVerdict
    stations: int
    """Stations sampled along the boundary (one raster cell apart)."""
    observed: int
    """Stations with at least one observed cell in their band."""
    curb_fraction: float
    """Observed stations with a curb cell in the band, over the observed stations (0 when none observed)."""
    edge_fraction: float
    """Observed stations with road on one side and off-road on the other, over the observed stations."""
    reason: str
    """Why the verdict, in words (`unobserved` has two: too little seen, or no road edge beside it)."""


@dataclass(frozen=True)
class KerbEvidence:
    """Each boundary element's verdict (element id -> verdict) and the evidence behind it."""

    verdicts: dict[str, KerbVerdict]
    evidence: dict[str, BoundaryEvidence]

    @property
    def counts(self) -> dict[str, int]:
        """Boundaries per verdict (every verdict listed, 0 included)."""
        values = list(self.verdicts.values())
        return {verdict: values.count(verdict) for verdict in KERB_VERDICTS}


def check_semantic(semantic: np.ndarray, georef: Georeference, *, name: str = "semantic") -> np.ndarray:
    """The raster as an int64 (H, W) array; ValueError naming `name` when it is not an integer raster of the
    georeference's (height, width)."""
    array = np.asarray(semantic)
    if array.ndim != 2 or array.shape != georef.shape:
        raise ValueError(
            f"{name}: semantic raster shape {array.shape} does not match the annotation set's georeference "
            f"(height, width) {georef.shape}"
        )
    if not np.issubdtype(array.dtype, np.integer):
        raise ValueError(f"{name}: semantic raster must hold integer class ids, got {array.dtype}")
    return array.astype(np.int64, copy=False)


def _band_labels(element: MapElement, semantic: np.ndarray, georef: Georeference) -> tuple[np.ndarray, float]:
    """(stations, 2n + 1) class ids across the line at each station (column n on the line, higher columns to
    its left), 255 outside the raster; and the mean spacing of the stations in metres."""
    step = georef.resolution
    stations = densify(element.xy(), step)[:, :2]
    tangent = np.gradient(stations, axis=0) if len(stations) > 1 else np.array([[1.0, 0.0]])
    norm = np.linalg.norm(tangent, axis=1, keepdims=True)
    tangent = np.where(norm > 0, tangent / np.where(norm > 0, norm, 1.0), [1.0, 0.0])
    normal = np.column_stack([-tangent[:, 1], tangent[:, 0]])  # to the left of the direction of travel
    half = max(1, round(BAND_M / step))
    offsets = np.arange(-half, half + 1) * step
    samples = stations[:, None, :] + offsets[None, :, None] * normal[:, None, :]
    colrow = np.rint(pixel_from_site_points(samples.reshape(-1, 2), georef)).astype(np.int64)
    col, row = colrow[:, 0], colrow[:, 1]
    height, width = semantic.shape
    inside = (row >= 0) & (row < height) & (col >= 0) & (col < width)
    labels = np.full(len(col), int(Semantic.UNOBSERVED), dtype=np.int64)
    labels[inside] = semantic[row[inside], col[inside]]
    length = float(np.linalg.norm(np.diff(stations, axis=0), axis=1).sum())
    return labels.reshape(len(stations), -1), length / max(len(stations) - 1, 1)


def boundary_evidence(element: MapElement, semantic: np.ndarray, georef: Georeference) -> BoundaryEvidence:
    """The verdict on one boundary (see the module docstring); `semantic` already checked (`check_semantic`)."""
    labels, spacing_m = _band_labels(element, semantic, georef)
    half = labels.shape[1] // 2
    seen = (labels != int(Semantic.UNOBSERVED)).any(axis=1)
    observed = int(seen.sum())
    if observed * spacing_m < MIN_OBSERVED_M or observed < MIN_OBSERVED_FRACTION * len(labels):
        reason = f"{observed} of {len(labels)} stations observed"
        return BoundaryEvidence("unobserved", len(labels), observed, 0.0, 0.0, reason)
    curb = (labels == int(Semantic.CURB)).any(axis=1)
    road = np.isin(labels, ROAD_SURFACE_IDS)
    off_road = labels == OFF_ROAD_ID
    left, right = slice(half + 1, None), slice(None, half)
    edge = (road[:, left].any(1) & off_road[:, right].any(1)) | (
        road[:, right].any(1) & off_road[:, left].any(1)
    )
    curb_fraction = float((curb & seen).sum()) / observed
    edge_fraction = float((edge & seen).sum()) / observed
    if curb_fraction >= KERB_MIN_FRACTION:
        verdict: KerbVerdict = "observed"
        reason = f"curb at {curb_fraction:.0%} of the observed stations"
    elif edge_fraction >= EDGE_MIN_FRACTION:
        verdict = "none"
        reason = f"road edge without curb at {edge_fraction:.0%} of the observed stations"
    else:
        verdict = "unobserved"
        reason = f"no kerb and no road edge beside it (road edge at {edge_fraction:.0%})"
    return BoundaryEvidence(verdict, len(labels), observed, curb_fraction, edge_fraction, reason)


def kerb_evidence(annotations: AnnotationSet, semantic: np.ndarray) -> KerbEvidence:
    """The verdict on every boundary element of the set from the semantic raster in its georeference;
    ValueError naming `semantic` when the raster does not fit the georeference."""
    georef = annotations.georeference
    labels = check_semantic(semantic, georef)
    evidence = {
        element.id: boundary_evidence(element, labels, georef) for element in annotations.by_class("boundary")
    }
    return KerbEvidence({key: item.verdict for key, item in evidence.items()}, evidence)
