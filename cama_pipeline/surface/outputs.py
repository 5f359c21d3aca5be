"""The surface stage's files in the workspace (`Workspace.surface_bev`, `surface_mesh`, `surface_report`); this
module is the only one that writes or reads them.

<workspace>/surface/<site_id>/mesh.ply      the observed road mesh (trimesh, binary PLY): global metres,
                                             per-vertex RGB colour and a `label` attribute (class 0-4)
<workspace>/surface/<site_id>/bev/          a BEV raster folder (`cama_pipeline.bev`), as a synthetic site's
                                             ground_truth/bev/: every layer; cells no camera ray hit are
                                             unobserved, observation_count counts the rays (keyframe pixels)
                                             that hit each cell, clipped at 65535
<workspace>/surface/<site_id>/kerb_step.npy float32 (rows, cols) on the BEV grid: metres the surface stands above
                                             the BEV elevation (the road surface vectors are lifted onto): the
                                             curb height on kerbs and raised sidewalks (`steps`), 0 elsewhere,
                                             NaN on unobserved cells; the mesh's heights include it
<workspace>/surface/<site_id>/report.json   schema "cama.surface/1", written last (marks completion):
    {"schema", "site_id", "fingerprint", "poses", "config": {...}, "images",
     "points": {"strip", "sfm", "sfm_kept" (SfM points past the gate, see `fit`)}, "vertices",
     "cells_observed", "seconds": {phase: s}, "losses": {"elevation": [huber + prior every 50 steps],
     "joint": [{"colour_l1", "semantic_ce", "loss", "rays_hitting"} per pass of `joint`],
     "epochs": [{"colour_l1", "semantic_ce", "anchor_huber"}]}, "kerb_step": {"height_m", "cells_raised",
     "off_road_share_raised"}, "weak_observation": {...} (`coverage`)}
"""

from pathlib import Path
from typing import Any

import numpy as np
import trimesh
from trimesh.exchange.ply import export_ply

from cama_pipeline.bev import BevRasters
from cama_pipeline.io import atomic_write_bytes, atomic_write_json, atomic_write_npy, read_json
from cama_pipeline.semantics import Semantic
from cama_pipeline.surface.grid import SurfaceGrid
from cama_pipeline.workspace import Workspace

REPORT_SCHEMA = "cama.surface/1"
MAX_COUNT = np.iinfo(np.uint16).max


def is_surface_bev(folder: Path) -> bool:
    """Whether a raster folder is a surface stage's `bev/` (reconstructed rasters: its finished report beside it),
    not a generator's ground truth; proposers treat the two differently (smeared curbs)."""
    try:
        workspace, site_id = Workspace.locate(folder)
    except ValueError:
        return False
    report = workspace.surface_report(site_id)
    if not report.is_file():
        return False
    try:
        read_report(report)
    except ValueError:
        return False
    return True


def rasters_from_vertices(
    grid: SurfaceGrid, heights: np.ndarray, colour: np.ndarray, label: np.ndarray, count: np.ndarray
) -> BevRasters:
    """Every raster layer from per-vertex values; cells whose count rounds to 0 stay unobserved (255 / NaN / black)."""
    rows, cols = grid.vertex_cells()
    rays = np.minimum(np.round(count), MAX_COUNT).astype(np.uint16)
    seen = rays > 0
    r, c = rows[seen], cols[seen]
    semantic = np.full((grid.rows, grid.cols), int(Semantic.UNOBSERVED), np.uint8)
    semantic[r, c] = label[seen]
    photometric = np.zeros((grid.rows, grid.cols, 3), np.uint8)
    photometric[r, c] = np.round(np.clip(colour[seen], 0, 1) * 255).astype(np.uint8)
    elevation = np.full((grid.rows, grid.cols), np.nan, np.float32)
    elevation[r, c] = heights[seen]
    observation = np.zeros((grid.rows, grid.cols), np.uint16)
    observation[r, c] = rays[seen]
    return BevRasters(grid.georeference(), semantic, photometric, elevation, observation)


def kerb_step_raster(grid: SurfaceGrid, step: np.ndarray, count: np.ndarray) -> np.ndarray:
    """(rows, cols) float32 from the (V,) per-vertex step: NaN where unobserved, as `rasters_from_vertices`."""
    rows, cols = grid.vertex_cells()
    seen = np.round(count) > 0
    raster = np.full((grid.rows, grid.cols), np.nan, np.float32)
    raster[rows[seen], cols[seen]] = step[seen]
    return raster


def write_kerb_step(path: Path, raster: np.ndarray) -> None:
    """kerb_step.npy, atomically."""
    atomic_write_npy(path, raster.astype(np.float32))


def read_kerb_step(path: Path, shape: tuple[int, int]) -> np.ndarray:
    """A stored kerb step raster; ValueError naming the file when it does not fit a (rows, cols) grid."""
    raster = np.load(path)
    if raster.shape != shape or raster.dtype != np.float32:
        raise ValueError(f"{path}: kerb step raster {raster.dtype} {raster.shape}, expected float32 {shape}")
    return raster


def grid_mesh(grid: SurfaceGrid, rasters: BevRasters, kerb_step: np.ndarray) -> trimesh.Trimesh:
    """The observed cells as a triangle mesh, standing on the kerb steps (`kerb_step`, metres above the
    elevation layer): two upward-facing triangles per square of observed cells."""
    semantic, rgb = rasters.require("semantic"), rasters.require("photometric")
    observed = semantic != int(Semantic.UNOBSERVED)
    index = np.full(observed.shape, -1, np.int64)
    index[observed] = np.arange(int(observed.sum()))
    rows, cols = np.nonzero(observed)
    xy = grid.xy_of_cells(rows, cols)
    vertices = np.column_stack([xy, rasters.require("elevation")[rows, cols] + kerb_step[rows, cols]])
    a, b = index[:-1, :-1], index[:-1, 1:]
    c, d = index[1:, :-1], index[1:, 1:]
    full = (a >= 0) & (b >= 0) & (c >= 0) & (d >= 0)
    faces = np.concatenate(
        [np.stack([a[full], c[full], d[full]], 1), np.stack([a[full], d[full], b[full]], 1)], axis=0
    )
    colours = np.column_stack([rgb[rows, cols], np.full(len(rows), 255, np.uint8)])
    mesh = trimesh.Trimesh(vertices, faces, vertex_colors=colours, process=False)
    mesh.vertex_attributes["label"] = semantic[rows, cols].astype(np.uint8)
    return mesh


def write_mesh(path: Path, mesh: trimesh.Trimesh) -> None:
    """Binary PLY, atomically."""
    atomic_write_bytes(path, export_ply(mesh))


def write_report(path: Path, report: dict[str, Any]) -> dict[str, Any]:
    """report.json atomically; written last, its fingerprint marks the site complete. Returns what was written."""
    stored = {"schema": REPORT_SCHEMA, **report}
    atomic_write_json(path, stored, indent=1)
    return stored


def read_report(path: Path) -> dict[str, Any]:
    """A stored report, schema-checked."""
    return read_json(path, REPORT_SCHEMA, "cama surface")
