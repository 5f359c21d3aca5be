"""How far the element-mask network's boundaries lie on the road's side of the true kerbs on reconstructions, and
what moving them off the road by that offset saves the annotator, in one run.

On each `--site`'s reconstruction (a synthetic site with a finished workspace, `reconstruction_of`) the promoted
network of `--checkpoint` predicts once. Its boundaries as the band alone traces them (`boundary_outward_m = 0`)
are measured against the observed true boundaries at stations every metre along the truth: where the proposed
line crosses the truth's normal (within `REACH_M`), its signed offset, positive on the road's side
(`element_masks.propose.road_side` of the truth's station); beside it, where the raster's road ends along the same
normal (the first road cell of the road's run), the cause the band follows. Their median is what
`MaskInferenceConfig.boundary_outward_m` is set to from the gate reconstructions. Then both settings, the band alone
and the product's (boundaries moved off the road by `boundary_outward_m`), are reviewed by the scripted annotator
(`review_time`) with each boundary's Chamfer distance, farthest point and acceptance (`bench/boundary_evidence.py`'s
`boundary_errors`), and the product's correction time is compared with the band's, with the confidence that the
saving holds across sites (`saving_confidence`, the gate's bootstrap). A checkpoint is refused on a site it saw
(`ensure_unseen`).

Usage: .venv/bin/python bench/boundary_offset.py --site data/synthetic/random-9113 [--site ...]
       [--checkpoint models/vma/element_masks/checkpoints] [--threads 2] [--out bench/results/boundary_offset.json]
"""

import sys
from pathlib import Path
from typing import Any

import numpy as np
from shapely.geometry import LineString

from app.review_effort.plan import Polyline
from app.review_effort.review_time import MIN_CONFIDENCE
from app.review_effort.truth import observed_true_polylines
from cama_pipeline.semantics import ROAD_SURFACE_IDS
from models.vma.element_masks.net import ElementMaskNet
from models.vma.element_masks.propose import (
    MaskInferenceConfig,
    predict_probabilities,
    road_side,
    vectors_from_probabilities,
)
from models.vma.raster_rays import labels_at
from models.vma.rasters import SiteRasters, load_site_rasters
from models.vma.validation import ValidationSite
from models.vma.vectors import Vector

# the shared conditions: `bench` is a package at the repository root
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from bench.boundary_evidence import boundary_errors, setting_figures  # noqa: E402
from bench.vma_measures import against_baseline, compare_settings, setting_of, settings_bench  # noqa: E402

RESULTS = Path(__file__).parent / "results"
SETTINGS: dict[str, dict[str, Any]] = {"band": {"boundary_outward_m": 0.0}, "product": {}}
"""Name of each setting in the results -> the `MaskInferenceConfig` fields it sets (the product: none)."""
BASELINE = "band"
STATION_M = 1.0
"""Spacing of the stations along each true boundary."""
REACH_M = 1.0
"""A proposed boundary crossing a station's normal farther than this from the truth is not that kerb's."""
EDGE_PROBES_M = np.arange(-1.5, 1.5 + 1e-9, 0.05)
"""Offsets across the truth (positive on the road's side) at which the raster's labels are read."""


def station_offsets(
    rasters: SiteRasters, proposals: list[Vector], truths: list[Polyline]
) -> list[tuple[float, float]]:
    """(proposal offset, road-edge offset) in metres, positive on the road's side of the truth, at each station of
    every true boundary that a proposed boundary crosses within `REACH_M` and whose road side the raster tells;
    the road-edge offset is NaN where the road's run does not end within the probes."""
    lines = [LineString(v.points) for v in proposals if v.cls == "boundary" and v.score >= MIN_CONFIDENCE]
    out = []
    for truth in (t for t in truths if t.cls == "boundary"):
        line = LineString(truth.points)
        for along in np.arange(0.5 * STATION_M, line.length - 0.5 * STATION_M + 1e-9, STATION_M):
            at = np.array(line.interpolate(along).coords[0])
            ahead = np.array(line.interpolate(min(along + 0.3, line.length)).coords[0])
            behind = np.array(line.interpolate(max(along - 0.3, 0.0)).coords[0])
            tangent = (ahead - behind) / max(float(np.linalg.norm(ahead - behind)), 1e-9)
            normal = np.array([-tangent[1], tangent[0]])
            side = float(road_side(rasters, at[None], normal[None])[0])
            crossing = _nearest_crossing(lines, at, side * normal)
            if side == 0 or crossing is None:
                continue
            out.append((crossing, _road_edge(rasters, at, side * normal)))
    return out


def _nearest_crossing(lines: list[LineString], at: np.ndarray, towards_road: np.ndarray) -> float | None:
    """Signed distance (along `towards_road`) of the nearest crossing of a proposed line with the station's normal."""
    normal = LineString([at - REACH_M * towards_road, at + REACH_M * towards_road])
    offsets = []
    for line in lines:
        hit = line.intersection(normal)
        points = [hit] if hit.geom_type == "Point" else getattr(hit, "geoms", [])
        offsets += [
            float((np.array(p.coords[0]) - at) @ towards_road) for p in points if p.geom_type == "Point"
        ]
    return min(offsets, key=abs) if offsets else None


def _road_edge(rasters: SiteRasters, at: np.ndarray, towards_road: np.ndarray) -> float:
    """Offset of the first road cell of the road's run that reaches the probes' road-side end (NaN: none)."""
    road = np.isin(
        labels_at(rasters, at[None] + EDGE_PROBES_M[:, None] * towards_road[None]), ROAD_SURFACE_IDS
    )
    if not road[-1] or road.all():
        return float("nan")
    return float(EDGE_PROBES_M[len(road) - int(np.argmin(road[::-1]))])


def offset_figures(rows: list[tuple[float, float]]) -> dict[str, Any]:
    """Median and quantiles of both offsets over the stations, and how closely the proposals follow the edge."""
    proposal = np.array([r[0] for r in rows])
    edge_at = np.array([r[1] for r in rows])
    found = np.isfinite(edge_at)
    edge = edge_at[found]
    quantiles = (0.1, 0.25, 0.5, 0.75, 0.9)
    return {
        "stations": len(rows),
        "proposal_median_roadward_m": float(np.median(proposal)) if len(proposal) else None,
        "proposal_quantiles_m": dict(
            zip(map(str, quantiles), np.quantile(proposal, quantiles).tolist(), strict=True)
        )
        if len(proposal)
        else None,
        "proposal_beyond_0_2_m_share": float(np.mean(np.abs(proposal) > 0.2)) if len(proposal) else None,
        "road_edge_stations": int(len(edge)),
        "road_edge_median_roadward_m": float(np.median(edge)) if len(edge) else None,
        "road_edge_quantiles_m": dict(
            zip(map(str, quantiles), np.quantile(edge, quantiles).tolist(), strict=True)
        )
        if len(edge)
        else None,
        "proposal_road_edge_correlation": float(np.corrcoef(proposal[found], edge)[0, 1])
        if len(edge) > 2 and np.std(edge) > 0 and np.std(proposal[found]) > 0
        else None,
    }


def band_offsets(sites: list[ValidationSite], model: ElementMaskNet) -> dict[str, Any]:
    """The band's boundaries (no outward move) against the truth at every station of every site."""
    config = MaskInferenceConfig(boundary_outward_m=0.0)
    rows: list[tuple[float, float]] = []
    for site in sites:
        rasters = load_site_rasters(site.rasters)
        proposals = vectors_from_probabilities(rasters, predict_probabilities(model, rasters, config), config)
        rows += station_offsets(rasters, proposals, observed_true_polylines(site.site, rasters, site.frame))
    return offset_figures(rows)


def measure(sites: list[ValidationSite], model: ElementMaskNet) -> dict[str, Any]:
    """The band's offsets, then both settings on every site (the network run once a site for them)."""
    settings = {name: setting_of(fields) for name, fields in SETTINGS.items()}
    compared = compare_settings(sites, model, settings, boundary_errors)
    return {
        "band_offsets": band_offsets(sites, model),
        "product_outward_m": MaskInferenceConfig().boundary_outward_m,
        "settings": {name: setting_figures(c["rows"], c["annotator"]) for name, c in compared.items()},
    }


def summary(figures: dict[str, Any]) -> dict[str, Any]:
    """The report's figures: the offsets, both settings, and the product's correction time against the band's."""
    return {**figures, "against_band": against_baseline(figures["settings"], BASELINE)}


def main() -> None:
    settings_bench(
        "bench/boundary_offset.py",
        __doc__.splitlines()[0],
        RESULTS / "boundary_offset.json",
        measure,
        summary,
    )


if __name__ == "__main__":
    main()
