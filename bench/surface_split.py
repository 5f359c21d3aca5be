"""Where the surface's class and colour errors come from: the same observation with better and better geometry.

`bench/surface.py` measures the surface as the stage makes it; this splits its error. With true poses, the
stage runs four times on one site, each comparing the same images through another surface:
  vote            the elevation fitted to points alone (`refine.enabled false`): the stage before the refinement;
  refined         the stage as it is (the multi-view refinement of the road elevation, `surface.refine`);
  true road       the true elevation on the true road cells (road, marking, crosswalk) and the fitted one
                  elsewhere, kerb steps as the stage decides them: the ceiling of any road-elevation method;
  true surface    the true elevation everywhere, sidewalks and kerb tops raised as they are (no curb-height vote,
                  no kerb step): the ceiling of any geometry at all.
The gap between "vote" and "true road" is what the road's height costs; between "true road" and "true surface"
what the kerbs cost; what "true surface" still misses comes from the vote itself (cells, masks, resolution).
With `--poses sfm` the same four runs use the site workspace's SfM poses, and the true heights are raised by the
SfM frame's height offset (the refined run's median road height error within `NEAR_TRAJECTORY_M` of the track,
which no surface fitted to those cameras can remove): "true surface" is then the true shape as those cameras
would see it in place, so what it misses against its true-pose run is what the poses cost.
The true heights are put in by wrapping `ControlGrid.at_vertices` (the one place the stage reads vertex
heights): the true height replaces the fitted one, and a shift of the surface (the curb-height vote) stays a
shift. An oracle for measurement only: the true elevation is never an input of the product.

Usage: .venv/bin/python bench/surface_split.py [--site data/synthetic/default] [--poses ground_truth|sfm]
       [--threads 1] [--out bench/results/surface_split.json]
"""

import argparse
import platform
import shutil
import sys
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import torch

from cama_pipeline.bev import BevRasters, read_bev
from cama_pipeline.io import atomic_write_json
from cama_pipeline.semantics import ROAD_SURFACE_IDS
from cama_pipeline.surface import SurfaceConfig
from cama_pipeline.surface import stage as surface_stage
from cama_pipeline.surface.elevation import ControlGrid
from cama_pipeline.surface.optimise import Mesh
from cama_pipeline.synthetic.truth_grid import nearest_true_cells

# the shared conditions: `bench` is a package at the repository root
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from bench.surface import RESULTS, run_source  # noqa: E402


def true_heights(mesh: Mesh, truth: BevRasters, road_only: bool, offset_m: float = 0.0) -> torch.Tensor:
    """(V,) the true elevation plus `offset_m` at each vertex (nearest true cell; the fitted one where the truth
    has none, and off the true road when `road_only`)."""
    with torch.no_grad():
        fitted = mesh.control.at_vertices(mesh.control_heights()).cpu().numpy()
    inside, rows, cols = nearest_true_cells(mesh.vertex_xy.cpu().numpy(), truth)
    height = truth.require("elevation")[rows, cols]
    use = inside & np.isfinite(height)
    if road_only:
        use &= np.isin(truth.require("semantic")[rows, cols], ROAD_SURFACE_IDS)
    return torch.as_tensor(
        np.where(use, height + offset_m, fitted), dtype=torch.float32, device=mesh.vertex_xy.device
    )


@contextmanager
def oracle_heights(truth: BevRasters, road_only: bool, offset_m: float = 0.0) -> Iterator[None]:
    """While open, the stage's vertices stand at the true heights raised by `offset_m` (see the module
    docstring)."""
    original_at_vertices = ControlGrid.at_vertices
    original_refine = surface_stage.refine_elevation
    state: dict[str, torch.Tensor] = {}

    def at_vertices(self: ControlGrid, control_z: torch.Tensor, vertex_ids: torch.Tensor | None = None):  # type: ignore[no-untyped-def]
        heights = original_at_vertices(self, control_z, vertex_ids)
        if "true" not in state:
            return heights
        true, fitted = state["true"], original_at_vertices(self, state["control_z"], vertex_ids)
        return heights - fitted + (true if vertex_ids is None else true[vertex_ids])

    def refine(mesh: Mesh, *args: Any, **kwargs: Any) -> list[dict[str, float]]:
        state.clear()
        state["true"] = true_heights(mesh, truth, road_only, offset_m)
        state["control_z"] = mesh.control_heights().detach()
        return []

    ControlGrid.at_vertices = at_vertices  # type: ignore[method-assign]
    surface_stage.refine_elevation = refine
    try:
        yield
    finally:
        ControlGrid.at_vertices = original_at_vertices  # type: ignore[method-assign]
        surface_stage.refine_elevation = original_refine


def figures(row: dict[str, Any]) -> dict[str, Any]:
    return {
        "elevation_rmse_m": row["elevation_rmse_m"],
        "iou": row["iou"],
        "psnr_db": row["psnr_db"],
        "psnr_affine_db": row["psnr_affine_db"],
        "curb_confusion": row["curb_confusion"],
        "curb_cells_rmse_m": row["kerb"]["elevation_rmse_m_curb_cells"],
        "elevation_median_signed_m_near_trajectory": row["elevation_median_signed_m_near_trajectory"],
        "seconds": row["seconds"],
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--site", type=Path, default=Path("data/synthetic/default"))
    parser.add_argument("--poses", choices=("ground_truth", "sfm"), default="ground_truth")
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--out", type=Path, default=RESULTS / "surface_split.json")
    args = parser.parse_args()
    config = SurfaceConfig(torch_threads=args.threads)
    vote = replace(config, refine=replace(config.refine, enabled=False))
    level = replace(vote, curb_height_m=0.0, kerb_step=replace(config.kerb_step, enabled=False))
    truth = read_bev(args.site / "ground_truth" / "bev")
    scratch = Path(tempfile.mkdtemp(prefix="bench-surface-split-"))
    runs: dict[str, dict[str, Any]] = {}
    try:
        runs["vote"] = figures(run_source(args.site, args.poses, vote, scratch))
        runs["refined"] = figures(run_source(args.site, args.poses, config, scratch))
        offset = runs["refined"]["elevation_median_signed_m_near_trajectory"] if args.poses == "sfm" else 0.0
        with oracle_heights(truth, road_only=True, offset_m=offset):
            runs["true_road"] = figures(run_source(args.site, args.poses, vote, scratch))
        with oracle_heights(truth, road_only=False, offset_m=offset):
            runs["true_surface"] = figures(run_source(args.site, args.poses, level, scratch))
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    print(f"{'':>14}" + "".join(f"{name:>14}" for name in runs))
    print(f"{'RMSE road cm':>14}" + "".join(f"{r['elevation_rmse_m'] * 100:>14.2f}" for r in runs.values()))
    for name in runs["vote"]["iou"]:
        print(f"{'IoU ' + name:>14}" + "".join(f"{r['iou'][name]:>14.3f}" for r in runs.values()))
    print(f"{'PSNR dB':>14}" + "".join(f"{r['psnr_db']:>14.2f}" for r in runs.values()))
    atomic_write_json(
        args.out,
        {
            "command": " ".join([sys.executable.split("/")[-1], *sys.argv]),
            "site": str(args.site),
            "poses": args.poses,
            "true_heights_offset_m": offset,
            "machine": {"platform": platform.platform(), "torch": torch.__version__},
            "runs": runs,
        },
        indent=1,
    )
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
