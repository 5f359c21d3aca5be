"""Where the SfM road points' height noise comes from: each point the surface stage may fit to, against the true
ground, split by what the SfM model knows of it.

The surface stage fits the road's elevation to the trajectory strip and to the SfM points labelled road, lane
marking or crosswalk whose mean reprojection error is at most `surface.sfm_max_error_px`
(`cama_pipeline.surface.points`); the fit's Huber loss and its gate against the strip's surface carry their noise.
For every such point of a finished `cama sfm` run this takes from the merged model (`sfm/<site>/model`): its
triangulation angle (the widest angle between two of the rays that observe it), its range (the distance to the
nearest camera that observes it), its track length, its mean reprojection error and its label (`points.npz`); and
its height error: the point carried into the true world by the best 3D similarity of the model's camera centres onto
the true ones, less the true ground's height under it. The points are binned by each property: their share, and the
median, 90th percentile and share beyond 10 cm of the absolute height error; the same for the points the stage's
elevation fit keeps after its gate (`fit_surface` rerun on the strip under the SfM poses), per label, and for the
points whose ground is not road at all. The camera centres' RMS distance to the true ones after the similarity says
how much of the error the poses could explain.

Usage: .venv/bin/python bench/sfm_point_error.py --site SITE [--site SITE ...]
       [--out bench/results/sfm_point_error.json]
"""

import argparse
import logging
import platform
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pycolmap
import torch
from scipy.spatial import cKDTree

from cama_pipeline.cameras import CameraView, site_views
from cama_pipeline.data import Dataset, load_dataset
from cama_pipeline.evaluate.errors import umeyama_alignment
from cama_pipeline.io import atomic_write_json
from cama_pipeline.semantics import BEV_CLASSES, ROAD_SURFACE_IDS, Semantic
from cama_pipeline.sfm.io import read_model, read_points
from cama_pipeline.site.io import read_site_ids, read_site_manifest
from cama_pipeline.surface import SurfaceConfig
from cama_pipeline.surface.fit import fit_surface
from cama_pipeline.surface.points import surface_points
from cama_pipeline.surface.poses import posed_views
from cama_pipeline.synthetic.truth_grid import TrueGround
from cama_pipeline.workspace import Workspace

RESULTS = Path(__file__).parent / "results"
ALL_CLASSES = tuple(int(c) for c in BEV_CLASSES)
"""The true ground's height under a point whatever its class: a point labelled road on a kerb is a kerb high."""
FAR_M = 0.10
"""An error beyond this counts as far off (a tenth of a metre: most of a kerb's height)."""
EDGES: dict[str, tuple[float, ...]] = {
    "triangulation_deg": (0, 2, 3, 5, 8, 12, 20, 180),
    "range_m": (0, 3, 5, 8, 12, 16, 20, 30, 1e9),
    "track_length": (2, 3, 4, 6, 10, 1e9),
    "reprojection_px": (0, 0.25, 0.5, 1.0, 1.5, 2.0 + 1e-9),
}
"""Bin edges of each property (a bin holds lower <= value < upper)."""


def ray_geometry(point: np.ndarray, centres: np.ndarray) -> tuple[float, float]:
    """(triangulation angle in degrees, range in metres) of a point seen from (K, 3) camera centres: the widest
    angle between two of its rays and the distance to the nearest centre."""
    rays = np.asarray(point, float) - np.asarray(centres, float)
    lengths = np.linalg.norm(rays, axis=1)
    units = rays / lengths[:, None]
    cosines = np.clip(units @ units.T, -1.0, 1.0)
    return float(np.degrees(np.arccos(cosines.min()))), float(lengths.min())


def model_geometry(model: pycolmap.Reconstruction, xyz: np.ndarray) -> dict[str, np.ndarray]:
    """Per point of (N, 3) `xyz` (points of `model`, matched by position): triangulation angle, range, track
    length; ValueError when a point is not one of the model's."""
    ids = sorted(model.points3D)
    positions = np.array([model.points3D[i].xyz for i in ids]).reshape(-1, 3)
    distance, index = cKDTree(positions).query(xyz)
    if len(xyz) and float(np.max(distance)) > 1e-6:
        raise ValueError(
            f"{int(np.sum(distance > 1e-6))} points are not the model's (farthest {distance.max():.3g} m)"
        )
    centres = {image_id: image.projection_center() for image_id, image in model.images.items()}
    angle, near, track = (np.zeros(len(xyz)) for _ in range(3))
    for row, point_index in enumerate(index):
        point = model.points3D[ids[point_index]]
        seen_from = np.array([centres[element.image_id] for element in point.track.elements])
        angle[row], near[row] = ray_geometry(point.xyz, seen_from)
        track[row] = len(seen_from)
    return {"triangulation_deg": angle, "range_m": near, "track_length": track}


def summary(errors: np.ndarray, total: int) -> dict[str, Any]:
    """Points `errors` (m) of `total`: their count and share, and the absolute errors' median and 90th percentile
    (cm) and share beyond `FAR_M`."""
    magnitude = np.abs(errors)
    return {
        "points": len(errors),
        "share": round(len(errors) / max(total, 1), 4),
        "median_cm": round(float(np.median(magnitude)) * 100, 2),
        "p90_cm": round(float(np.percentile(magnitude, 90)) * 100, 2),
        "beyond_10cm": round(float(np.mean(magnitude > FAR_M)), 4),
    }


def binned(values: np.ndarray, errors: np.ndarray, edges: Sequence[float]) -> list[dict[str, Any]]:
    """The `summary` of each non-empty bin of `values` (lower edge <= value < upper), with its bounds."""
    rows = []
    for lower, upper in zip(edges[:-1], edges[1:], strict=True):
        inside = (values >= lower) & (values < upper)
        if inside.any():
            rows.append({"from": lower, "to": upper, **summary(errors[inside], len(values))})
    return rows


def camera_centres(
    site: Path, dataset: Dataset, manifest: dict[str, Any], model: pycolmap.Reconstruction
) -> tuple[np.ndarray, np.ndarray]:
    """(K, 3) twice: the model's camera centres and the true ones, for the site's key-frame images in the model."""
    from sfm import true_world_from_cam  # bench/sfm.py, on sys.path when this runs as a script

    true = true_world_from_cam(site, site_views(dataset, manifest))
    ours = {image.name: image.projection_center() for image in model.images.values() if image.name in true}
    names = sorted(ours)
    return np.array([ours[name] for name in names]), np.array([true[name][:3, 3] for name in names])


def kept_by_fit(views: list[CameraView], xyz: np.ndarray, config: SurfaceConfig) -> np.ndarray:
    """(N,) whether the surface stage's elevation fit (`fit_surface`, on the strip under `views`, the SfM-posed key
    frames) keeps each of the SfM road points `xyz` after its gate."""
    points = surface_points(views, xyz, config)
    fitted = fit_surface(points, config, torch.device("cpu"))
    kept = fitted.points[points.strip_count :].cpu().numpy()
    if not len(kept):
        return np.zeros(len(xyz), dtype=bool)
    distance, _ = cKDTree(kept).query(xyz)
    return np.asarray(distance < 1e-9)


def measure(site: Path, config: SurfaceConfig) -> dict[str, Any]:
    """The site's SfM road points that the surface stage may fit to, split by each property, for all of them and
    for those its elevation fit keeps (module docstring)."""
    workspace = Workspace.for_dataset(site / "nuscenes")
    site_id = read_site_ids(workspace.sites_index())[0]
    points_path = workspace.sfm_points(site_id)
    if not points_path.is_file():
        raise SystemExit(f"{site}: no SfM points at {points_path} (run `cama sfm` first)")
    points = read_points(points_path)
    model = read_model(points_path.parent / "model")
    dataset = load_dataset(site / "nuscenes")
    manifest = read_site_manifest(workspace.site_manifest(site_id))
    usable = np.isin(points.label, ROAD_SURFACE_IDS) & (points.error_px <= config.sfm_max_error_px)
    xyz = points.xyz[usable]
    ours, true = camera_centres(site, dataset, manifest, model)
    rotation, translation, scale = umeyama_alignment(ours, true, with_scale=True)
    world = scale * xyz @ rotation.T + translation
    ground = TrueGround.of(site)
    error = world[:, 2] - ground.height_of(ALL_CLASSES)(world[:, :2])
    known = np.isfinite(error)  # the points over the true ground; every figure below is over these
    error, total = error[known], int(known.sum())
    on_road = np.isfinite(ground.height_of()(world[known, :2]))
    properties = {**model_geometry(model, xyz), "reprojection_px": points.error_px[usable]}
    properties = {name: values[known] for name, values in properties.items()}
    labels = points.label[usable][known]
    views = posed_views(dataset, manifest, workspace, site_id, "sfm")
    kept = kept_by_fit(views, xyz, config)[known]
    return {
        "site_id": site_id,
        **summary(error, total),
        "off_true_road": summary(error[~on_road], total),
        "camera_centres_after_similarity_cm": round(
            float(np.sqrt(np.mean(np.sum((scale * ours @ rotation.T + translation - true) ** 2, axis=1))))
            * 100,
            2,
        ),
        "by": {name: binned(values, error, EDGES[name]) for name, values in properties.items()},
        "kept_by_the_fit": summary(error[kept], total),
        "kept_by": {
            name: binned(values[kept], error[kept], EDGES[name]) for name, values in properties.items()
        },
        "by_label": {
            Semantic(label).name.lower(): summary(error[labels == label], total)
            for label in sorted(set(labels.tolist()))
        },
    }


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--site", type=Path, action="append", required=True, help="a site with its SfM run")
    parser.add_argument("--out", type=Path, default=RESULTS / "sfm_point_error.json")
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)
    config = SurfaceConfig()
    sites = {}
    for site in args.site:
        sites[site.name] = result = measure(site, config)
        print(
            f"{site.name}: {result['points']} points, median {result['median_cm']} cm, {result['beyond_10cm']:.0%} beyond 10 cm"
        )
        kept = result["kept_by_the_fit"]
        print(
            f"  kept by the fit: {kept['share']:.0%}, median {kept['median_cm']} cm, {kept['beyond_10cm']:.0%} beyond 10 cm"
        )
        for name, rows in result["by"].items():
            for row in rows:
                print(
                    f"  {name} [{row['from']:g}, {row['to']:g}): {row['share']:.1%} of the points, median"
                    f" {row['median_cm']} cm, p90 {row['p90_cm']} cm, {row['beyond_10cm']:.0%} beyond 10 cm"
                )
    atomic_write_json(
        args.out,
        {
            "command": " ".join(sys.argv),
            "machine": {"platform": platform.platform(), "python": platform.python_version()},
            "sfm_max_error_px": config.sfm_max_error_px,
            "sites": sites,
        },
        indent=1,
    )
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
