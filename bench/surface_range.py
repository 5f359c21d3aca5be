"""Where the road's height error grows with range, and why: the reconstruction against the plain extrapolation of
exact points, by distance from the camera track, beside the true terrain's curvature across the track.

`bench/surface.py` gives one RMSE per site; this splits it by distance from the track, where it grows. For each
`--site` (a synthetic site with `cama run` done):
  reconstruction  the surface stage's elevation raster as the workspace holds it (SfM poses, refined), on the
                  cells it labels road that are true road, carried into the world by the reconstruction's frame;
  extrapolation   the stage's elevation MLP and curvature prior fitted to the trajectory strip alone under the
                  true poses (exact points, no SfM points, no refinement): what a plane-like prior makes of the
                  road away from the points it has;
both against the true road elevation, each with its height offset within `NEAR_M` of the track taken out (the
SfM frame's offset is no shape error), per band of distance from the nearest true camera position: the median
error (positive: the surface stands too high), the RMS and the share beyond 4 cm. Beside them the true terrain's
curvature across the track (second difference of the true elevation at +-4 and +-8 m across each front camera's
heading; negative: the ground falls away on both sides, so a plane through the track stands above it).

Usage: .venv/bin/python bench/surface_range.py --site data/synthetic/random-9201 [--site ...] [--threads 2]
       [--out bench/results/surface_range.json]
"""

import argparse
import json
import platform
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import torch
from scipy.spatial import cKDTree

from cama_pipeline.bev import BevRasters, read_bev
from cama_pipeline.data import load_dataset
from cama_pipeline.io import atomic_write_json
from cama_pipeline.semantics import ROAD_SURFACE_IDS
from cama_pipeline.site.io import read_site_manifest
from cama_pipeline.surface import SurfaceConfig
from cama_pipeline.surface.fit import fit_surface
from cama_pipeline.surface.points import surface_points
from cama_pipeline.surface.poses import ground_truth_poses_path, posed_views
from cama_pipeline.workspace import Workspace
from models.vma.validation import reconstruction_of

RESULTS = Path(__file__).parent / "results"
BANDS_M = ((0, 2), (2, 4), (4, 6), (6, 8), (8, 10), (10, 12), (12, 15), (15, 25))
"""Distance bands from the camera track (metres)."""
NEAR_M = 4.0
"""Cells this close to the track set each surface's height offset (its median error there)."""
FAR_ERROR_M = 0.04
CURVATURE_SPANS_M = (4.0, 8.0)


def band_figures(distance: np.ndarray, error: np.ndarray) -> list[dict[str, Any]]:
    """Per distance band: cells, median error, RMS and the share beyond `FAR_ERROR_M` (metres)."""
    rows = []
    for lo, hi in BANDS_M:
        inside = (distance >= lo) & (distance < hi)
        e = error[inside]
        rows.append(
            {
                "band_m": [lo, hi],
                "cells": int(inside.sum()),
                "median_m": float(np.median(e)) if len(e) else None,
                "rms_m": float(np.sqrt(np.mean(e**2))) if len(e) else None,
                "beyond_4cm_share": float(np.mean(np.abs(e) > FAR_ERROR_M)) if len(e) else None,
            }
        )
    return rows


def without_offset(distance: np.ndarray, error: np.ndarray) -> np.ndarray:
    """`error` less its median within `NEAR_M` of the track (all of it when nothing is that near)."""
    near = distance < NEAR_M
    return error - float(np.median(error[near] if near.any() else error))


def true_elevation(truth: BevRasters, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(N,) the true elevation at global x, y (NaN outside) and whether the truth calls the cell road."""
    colrow = np.rint(truth.georeference.pixel_from_global(xy)).astype(int)
    col, row = colrow[:, 0], colrow[:, 1]
    height, width = truth.georeference.shape
    inside = (row >= 0) & (row < height) & (col >= 0) & (col < width)
    z = np.full(len(xy), np.nan)
    road = np.zeros(len(xy), bool)
    z[inside] = truth.require("elevation")[row[inside], col[inside]]
    road[inside] = np.isin(truth.require("semantic")[row[inside], col[inside]], ROAD_SURFACE_IDS)
    return z, road


def camera_track(site: Path) -> tuple[np.ndarray, np.ndarray]:
    """The true positions (N, 2) of every key-frame camera and the heading (radians) of each front camera."""
    poses = json.loads(ground_truth_poses_path(site / "nuscenes").read_text(encoding="utf-8")).values()
    positions = np.array([p["translation"][:2] for p in poses], dtype=np.float64)
    headings = []
    for p in poses:
        if p["channel"] == "CAM_FRONT":
            w, x, y, z = p["rotation"]
            headings.append((p["translation"][:2], np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))))
    return positions, np.array([[*xy, heading] for xy, heading in headings], dtype=np.float64)


def lateral_curvature(truth: BevRasters, fronts: np.ndarray) -> dict[str, Any]:
    """The true terrain's second difference across each front camera's heading (1/m), per span."""
    out: dict[str, Any] = {}
    for span in CURVATURE_SPANS_M:
        across = np.column_stack([-np.sin(fronts[:, 2]), np.cos(fronts[:, 2])])
        z = [true_elevation(truth, fronts[:, :2] + k * span * across)[0] for k in (-1, 0, 1)]
        curvature = (z[0] + z[2] - 2 * z[1]) / span**2
        curvature = curvature[np.isfinite(curvature)]
        out[f"{span:g}_m"] = {
            "median_per_m": float(np.median(curvature)) if len(curvature) else None,
            "negative_share": float(np.mean(curvature < 0)) if len(curvature) else None,
        }
    return out


def reconstruction_errors(site: Path, truth: BevRasters, track: cKDTree) -> tuple[np.ndarray, np.ndarray]:
    """(distance, error) on the reconstruction's road cells that are true road (world metres)."""
    validation = reconstruction_of(site)
    ours = read_bev(validation.rasters, ("semantic", "elevation"))
    rows, cols = np.nonzero(np.isin(ours.require("semantic"), ROAD_SURFACE_IDS))
    world = validation.frame.world_of(ours.georeference.global_from_pixel(np.column_stack([cols, rows])))
    z, road = true_elevation(truth, world)
    error = ours.require("elevation")[rows, cols] - z
    keep = road & np.isfinite(error)
    distance = track.query(world[keep])[0]
    return distance, without_offset(distance, error[keep])


def extrapolation_errors(site: Path, truth: BevRasters, track: cKDTree) -> tuple[np.ndarray, np.ndarray]:
    """(distance, error) of the elevation fitted to the true trajectory strip alone, on the true road cells of
    its region."""
    dataset_root = site / "nuscenes"
    workspace = Workspace.resolve(None, dataset_root)
    site_id = reconstruction_of(site).rasters.parent.name  # the one reconstructed site's id
    manifest = read_site_manifest(workspace.site_manifest(site_id))
    views = posed_views(load_dataset(dataset_root), manifest, workspace, site_id, "ground_truth")
    config = replace(SurfaceConfig(), use_sfm_points=False)
    fitted = fit_surface(surface_points(views, np.zeros((0, 3)), config), config, torch.device("cpu"))
    xy = fitted.grid.vertex_xy()
    z, road = true_elevation(truth, xy)
    with torch.no_grad():
        fit = fitted.mlp(torch.as_tensor(xy)).double().numpy()
    keep = road & np.isfinite(z)
    distance = track.query(xy[keep])[0]
    return distance, without_offset(distance, fit[keep] - z[keep])


def measure_site(site: Path) -> dict[str, Any]:
    """Both surfaces' errors by band and the terrain's curvature on one site, and the raw errors for pooling."""
    truth = read_bev(site / "ground_truth" / "bev", ("semantic", "elevation"))
    positions, fronts = camera_track(site)
    track = cKDTree(positions)
    recon = reconstruction_errors(site, truth, track)
    extrapolated = extrapolation_errors(site, truth, track)
    return {
        "figures": {
            "reconstruction": band_figures(*recon),
            "extrapolation": band_figures(*extrapolated),
            "lateral_curvature": lateral_curvature(truth, fronts),
        },
        "raw": {"reconstruction": recon, "extrapolation": extrapolated},
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--site", type=Path, action="append", required=True, help="synthetic site (repeatable)"
    )
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--out", type=Path, default=RESULTS / "surface_range.json")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    started = time.perf_counter()
    per_site, pooled = {}, {"reconstruction": [], "extrapolation": []}
    for site in args.site:
        measured = measure_site(site)
        per_site[str(site)] = measured["figures"]
        for name, raw in measured["raw"].items():
            pooled[name].append(raw)
        print(f"{site}: done", flush=True)
    report = {
        "command": "python bench/surface_range.py "
        + "".join(f"--site {s} " for s in args.site)
        + f"--threads {args.threads}",
        "sites": [str(s) for s in args.site],
        "pooled": {
            name: band_figures(np.concatenate([d for d, _ in raws]), np.concatenate([e for _, e in raws]))
            for name, raws in pooled.items()
        },
        "per_site": per_site,
        "machine": {"cpu_threads": args.threads, "platform": platform.platform(), "device": "cpu"},
        "seconds": round(time.perf_counter() - started, 1),
    }
    atomic_write_json(args.out, report)
    print(f"written to {args.out}")


if __name__ == "__main__":
    main()
