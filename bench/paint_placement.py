"""Where a reconstruction's rasters put the lane lines, against the truth in its frame, and why.

An annotator draws on the rasters, and the simulated annotator now works towards the truth carried into the
reconstruction's frame (`cama_pipeline.evaluate.frame`), so a global placement of the site costs nobody. What it
still counts against the proposer is paint the rasters show away from where the frame puts the truth: a
proposal on that paint is rejected or dragged. This measures it per true divider: stations every 0.5 m along the
line (in the frame) look across it, within `REACH_M` either side, for the rasters' lane-marking cells; the offset of
their centre from the true line is where the rasters show the paint there. Beside it, the surface's height error
along the line (the raster's elevation minus the truth's, less the site's median over all dividers: a height
offset of the whole site is the poses', like the frame, and moves nothing in the rasters) and the line's distance
from the trajectory (the nearest true keyframe ego position). Cameras at height h that look at paint L metres
away through a surface dz too high see it about dz * L / h nearer than it is, so a height error of a few
centimetres at the edge of what the cameras saw moves paint by decimetres.

Usage: .venv/bin/python bench/paint_placement.py --site data/synthetic/random-9007 [--site ...]
       [--out bench/results/paint_placement.json]
"""

import argparse
import platform
import sys
from pathlib import Path
from typing import Any

import numpy as np
from scipy.ndimage import map_coordinates
from scipy.spatial import cKDTree
from shapely.geometry import LineString

from app.review_effort.truth import observed_true_polylines
from cama_pipeline.bev import read_bev
from cama_pipeline.data import load_dataset
from cama_pipeline.io import atomic_write_json
from cama_pipeline.semantics import Semantic
from cama_pipeline.site.io import read_site_manifest
from cama_pipeline.surface.poses import posed_views
from cama_pipeline.synthetic.truth_grid import nearest_true_cells
from cama_pipeline.workspace import Workspace
from models.vma.rasters import SiteRasters, load_site_rasters
from models.vma.validation import reconstruction_of

# the shared conditions: `bench` is a package at the repository root
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from bench.surface import RESULTS  # noqa: E402

STATION_M = 0.5
REACH_M = 1.0
"""How far across the true line a station looks for the rasters' paint."""
DISPLACED_M = 0.25
"""Paint this far off its true line is beyond the simulated annotator's acceptance (Chamfer 0.25 m)."""


def true_trajectory(site: Path, site_id: str) -> np.ndarray:
    """(K, 2) the true ego positions of the keyframes of reconstructed site `site_id` (world metres)."""
    dataset_root = site / "nuscenes"
    workspace = Workspace.for_dataset(dataset_root)
    manifest = read_site_manifest(workspace.site_manifest(site_id))
    views = posed_views(load_dataset(dataset_root), manifest, workspace, site_id, "ground_truth")
    return np.array([v.world_from_ego[:2, 3] for v in views]).reshape(-1, 2)


def stations_along(line: LineString) -> tuple[np.ndarray, np.ndarray]:
    """(S, 2) points every `STATION_M` along `line` (the first half a step in) and (S, 2) the unit normals to its
    left there."""
    points, normals = [], []
    for distance in np.arange(STATION_M / 2, line.length, STATION_M):
        ahead = np.array(line.interpolate(min(distance + 0.2, line.length)).coords[0])
        behind = np.array(line.interpolate(max(distance - 0.2, 0.0)).coords[0])
        tangent = (ahead - behind) / max(float(np.linalg.norm(ahead - behind)), 1e-9)
        points.append(line.interpolate(distance).coords[0])
        normals.append([-tangent[1], tangent[0]])
    return np.array(points).reshape(-1, 2), np.array(normals).reshape(-1, 2)


def paint_offsets(
    rasters: SiteRasters, paint: np.ndarray, stations: np.ndarray, normals: np.ndarray
) -> np.ndarray:
    """(S,) the offset along each station's normal (frame metres, NaN where none) of the centre of the `paint`
    cells (float 0/1 on the rasters' grid) within `REACH_M` of it."""
    across = np.arange(-REACH_M, REACH_M + 1e-9, 0.25 * rasters.resolution_m)
    offsets = []
    for here, normal in zip(stations, normals, strict=True):
        colrow = rasters.pixel_from_global(here[None] + across[:, None] * normal[None])
        seen = map_coordinates(paint, [colrow[:, 1], colrow[:, 0]], order=0, mode="constant")
        offsets.append(float((seen * across).sum() / seen.sum()) if seen.sum() else np.nan)
    return np.asarray(offsets)


def lane_marking(rasters: SiteRasters) -> np.ndarray:
    """(H, W) float32 1 on the rasters' lane-marking cells."""
    return (rasters.semantic == int(Semantic.LANE_MARKING)).astype(np.float32)


def site_figures(site: Path) -> dict[str, Any]:
    """Per observed part of a true divider: where the rasters show its paint, the surface's height error under it,
    its distance from the trajectory; and the site's frame."""
    validation = reconstruction_of(site)
    frame = validation.frame
    assert frame is not None  # a reconstruction's
    rasters = load_site_rasters(validation.rasters)
    elevation = read_bev(validation.rasters).require("elevation")
    truth_bev = read_bev(site / "ground_truth" / "bev")
    true_elevation = truth_bev.require("elevation")
    trajectory = cKDTree(frame.apply(true_trajectory(site, validation.rasters.parent.name)))
    paint = lane_marking(rasters)
    dividers = []
    for polyline in observed_true_polylines(site, rasters, frame):
        line = LineString(polyline.points)
        if polyline.cls != "divider" or line.length < STATION_M:
            continue
        stations, normals = stations_along(line)
        offsets = paint_offsets(rasters, paint, stations, normals)
        colrow = rasters.pixel_from_global(stations)
        ours = map_coordinates(elevation, [colrow[:, 1], colrow[:, 0]], order=1, cval=np.nan)
        inside, rows, cols = nearest_true_cells(frame.world_of(stations), truth_bev)
        true_z = np.where(inside, true_elevation[rows, cols], np.nan)
        dividers.append(
            {
                "start_xy": [round(float(v), 2) for v in polyline.points[0]],
                "length_m": round(line.length, 2),
                "stations": len(offsets),
                "stations_with_paint": int(np.isfinite(offsets).sum()),
                "paint_offset_m": _median(offsets),
                "height_error_m": _median(ours - true_z),
                "distance_from_trajectory_m": float(np.median(trajectory.query(stations)[0])),
            }
        )
    site_height = _median(np.array([d["height_error_m"] for d in dividers], dtype=np.float64))
    for divider in dividers:
        if divider["height_error_m"] is not None and site_height is not None:
            divider["height_error_m"] -= site_height
    painted = [d for d in dividers if d["paint_offset_m"] is not None]
    displaced = [d for d in painted if abs(d["paint_offset_m"]) > DISPLACED_M]
    return {
        "site": str(site),
        "frame": frame.as_dict(),
        "site_height_offset_m": site_height,
        "dividers": dividers,
        "with_paint": len(painted),
        "displaced": len(displaced),
        "displaced_median_distance_m": _median(
            np.array([d["distance_from_trajectory_m"] for d in displaced])
        ),
        "in_place_median_distance_m": _median(
            np.array([d["distance_from_trajectory_m"] for d in painted if d not in displaced])
        ),
        "offset_height_distance_correlation": _correlation(painted),
    }


def _median(values: np.ndarray) -> float | None:
    finite = values[np.isfinite(values)]
    return float(np.median(finite)) if finite.size else None


def _correlation(dividers: list[dict[str, Any]]) -> float | None:
    """Pearson correlation, over the dividers, of how far the paint is off (|offset|) with how far a height error
    moves paint seen from the trajectory (|height error| x distance); None under three dividers."""
    pairs = np.array(
        [
            (abs(d["paint_offset_m"]), abs(d["height_error_m"]) * d["distance_from_trajectory_m"])
            for d in dividers
            if d["height_error_m"] is not None
        ]
    )
    if len(pairs) < 3:
        return None
    return float(np.corrcoef(pairs[:, 0], pairs[:, 1])[0, 1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--site", type=Path, action="append", required=True)
    parser.add_argument("--out", type=Path, default=RESULTS / "paint_placement.json")
    args = parser.parse_args()
    sites = [site_figures(site) for site in args.site]
    for figures in sites:
        print(
            f"{figures['site']}: {figures['displaced']} of {figures['with_paint']} dividers' paint more than "
            f"{DISPLACED_M} m off (median {figures['displaced_median_distance_m']} m from the trajectory, "
            f"against {figures['in_place_median_distance_m']} m); correlation of the offset with height error x "
            f"distance {figures['offset_height_distance_correlation']}"
        )
    atomic_write_json(
        args.out,
        {
            "command": " ".join([sys.executable.split("/")[-1], *sys.argv]),
            "machine": {"platform": platform.platform()},
            "displaced_m": DISPLACED_M,
            "sites": sites,
        },
        indent=1,
    )
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
