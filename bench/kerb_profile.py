"""Where the curb IoU is lost, across the kerb: the surface stage's decisions by distance from the true road edge.

`bench/surface.py` says how many true curb cells are labelled road or background; `bench/surface_split.py` that the
true kerb geometry would lift the curb IoU from 0.39 to 0.89. This says where across the kerb each of the stage's
inputs and decisions goes wrong. The stage runs once per pose source (as `bench/surface.py` runs it), and for every
observed vertex the bench keeps what the stage computed: the class shares of its views at road level and at curb
height (`labels.fused_logits`' inputs), the log ratio of the two colour variances (`steps.raised_vertices`'
score: positive where the views agree better at curb height), whether the step raised it, and its final label.

Vertices are binned by their signed distance from the true road edge (negative on the road, positive beyond it;
the true curb strip is the first 0.15-0.3 m beyond it, then the raised sidewalk), and each bin reports the true
curb share, the mean road-level and curb-height shares of road, curb and background, the median score, the
share raised, the shares labelled road, curb and background, and the share the vote would label right if it
read every cell at its true height (road cells at road level, off-road cells at curb height; argmax of those
shares): the decision of heights taken out, what the votes themselves allow. The same two readings give the road
and curb IoU near the kerbs (`band_iou`). Only vertices within `--max-distance` of a true road edge count, so
every off-road cell counted stands on a raised sidewalk (the generator's are 2.5-4.5 m wide).

`--masks` chooses the masks the stage observes through (on a mask-free site the segmenter's, or `generator`: the
masks its `ground_truth/` keeps), so the same SfM run profiled twice says where across the kerb the segmenter's masks
lose; `--frame own` carries the truth into the reconstruction's frame (the best 2D similarity of its key frames onto
the true ones), taking out the SfM frame's few centimetres of placement, which is half a kerb's width.

Usage: .venv/bin/python bench/kerb_profile.py [--site data/synthetic/default] [--sources ground_truth,sfm]
       [--kerb-band M] [--kerb-line on|off] [--masks auto|predicted|...|generator] [--frame world|own]
       [--threads 1] [--out bench/results/kerb_profile.json]
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
from scipy import ndimage

from cama_pipeline.bev import BevRasters, RasterGeoreference
from cama_pipeline.evaluate.frame import reconstruction_frame
from cama_pipeline.io import atomic_write_json
from cama_pipeline.semantics import BEV_CLASSES, ROAD_SURFACE_IDS, Semantic
from cama_pipeline.surface import SurfaceConfig
from cama_pipeline.surface import optimise as surface_optimise
from cama_pipeline.surface import stage as surface_stage
from cama_pipeline.surface.labels import shares
from cama_pipeline.surface.steps import curb_height_agreement
from cama_pipeline.synthetic.truth_grid import nearest_true_cells, truth_on_grid
from cama_pipeline.workspace import Workspace

# the shared conditions: `bench` is a package at the repository root
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from bench.surface import RESULTS, run_source  # noqa: E402

BIN_M = 0.1
SHOWN = {"road": Semantic.ROAD, "curb": Semantic.CURB, "background": Semantic.BACKGROUND}
"""The classes whose shares each bin reports."""


def signed_edge_distance(truth: BevRasters) -> np.ndarray:
    """(rows, cols) metres from the true road edge: negative on the road classes, positive off them."""
    road = np.isin(truth.require("semantic"), ROAD_SURFACE_IDS)
    resolution = truth.georeference.resolution
    outside = ndimage.distance_transform_edt(~road, sampling=resolution)
    inside = ndimage.distance_transform_edt(road, sampling=resolution)
    return np.where(road, -inside, outside)


def true_height_labels(true_class: np.ndarray, road_level: np.ndarray, curb_height: np.ndarray) -> np.ndarray:
    """(N,) the class each cell's views give at its true height: the road-level vote's argmax on the true road
    classes, the curb-height vote's argmax elsewhere (off-road cells near a kerb stand on the raised sidewalk)."""
    on_road = np.isin(true_class, ROAD_SURFACE_IDS)
    best = np.where(on_road, road_level.argmax(axis=1), curb_height.argmax(axis=1))
    return np.asarray([int(c) for c in BEV_CLASSES])[best]


def band_iou(label: np.ndarray, true_class: np.ndarray) -> dict[str, float]:
    """IoU of road and curb between (N,) labels and true classes of the cells near the kerbs."""
    ious = {}
    for name in ("road", "curb"):
        ours, truth = label == int(SHOWN[name]), true_class == int(SHOWN[name])
        ious[name] = float((ours & truth).sum() / max((ours | truth).sum(), 1))
    return ious


def profile(
    distance: np.ndarray,
    true_class: np.ndarray,
    road_level: np.ndarray,
    curb_height: np.ndarray,
    score: np.ndarray,
    raised: np.ndarray,
    label: np.ndarray,
    edges: np.ndarray,
) -> list[dict[str, Any]]:
    """Per bin [edges[i], edges[i + 1]) of the (N,) signed `distance`: the figures of the module docstring, from
    (N,) true classes, (N, 5) class shares at road level and at curb height (columns in `BEV_CLASSES` order),
    (N,) scores, (N,) raised flags and (N,) final labels."""
    columns = {name: BEV_CLASSES.index(cls) for name, cls in SHOWN.items()}
    right_at_true_height = true_height_labels(true_class, road_level, curb_height) == true_class
    rows = []
    for low, high in zip(edges[:-1], edges[1:], strict=True):
        m = (distance >= low) & (distance < high)
        if not m.any():
            continue
        rows.append(
            {
                "from_m": round(float(low), 3),
                "to_m": round(float(high), 3),
                "cells": int(m.sum()),
                "true_curb_share": float(np.mean(true_class[m] == int(Semantic.CURB))),
                "road_level_shares": {k: float(road_level[m, c].mean()) for k, c in columns.items()},
                "curb_height_shares": {k: float(curb_height[m, c].mean()) for k, c in columns.items()},
                "median_score": float(np.median(score[m])),
                "raised_share": float(raised[m].mean()),
                "labelled": {k: float(np.mean(label[m] == int(cls))) for k, cls in SHOWN.items()},
                "right_at_true_height": float(right_at_true_height[m].mean()),
                "right": float(np.mean(label[m] == true_class[m])),
            }
        )
    return rows


@contextmanager
def captured_decisions() -> Iterator[dict[str, Any]]:
    """While open, the observation pass's class votes, kerb-step inputs and outputs and final labels of the last
    run are kept in the yielded dict (the stage's own functions, wrapped; nothing it computes changes)."""
    original_fused, original_raised = surface_optimise.fused_logits, surface_optimise.raised_vertices
    original_rasters = surface_stage.rasters_from_vertices
    kept: dict[str, Any] = {}

    def fused_logits(ground: torch.Tensor, raised: torch.Tensor | None) -> torch.Tensor:
        kept["road_level"] = shares(ground).cpu().numpy()
        kept["curb_height"] = None if raised is None else shares(raised).cpu().numpy()
        return original_fused(ground, raised)

    def raised_vertices(grid, road_level, curb_level, off_road, painted, config):  # type: ignore[no-untyped-def]
        result = original_raised(grid, road_level, curb_level, off_road, painted, config)
        weight = road_level.weight.cpu().numpy()
        score = curb_height_agreement(road_level, curb_level)
        kept.update(grid=grid, seen=weight > 0, observed=np.round(weight) > 0, score=score)
        kept["raised"] = result[0]
        return result

    def rasters_from_vertices(grid, heights, colour, label, count):  # type: ignore[no-untyped-def]
        kept["label"] = label.copy()
        return original_rasters(grid, heights, colour, label, count)

    surface_optimise.fused_logits = fused_logits
    surface_optimise.raised_vertices = raised_vertices
    surface_stage.rasters_from_vertices = rasters_from_vertices
    try:
        yield kept
    finally:
        surface_optimise.fused_logits = original_fused
        surface_optimise.raised_vertices = original_raised
        surface_stage.rasters_from_vertices = original_rasters


def source_profile(
    site: Path,
    poses: str,
    config: SurfaceConfig,
    scratch: Path,
    max_distance_m: float,
    masks: str = "auto",
    frame: str = "world",
) -> dict[str, Any]:
    """Run the stage with `poses`, observing through `masks` (`bench/surface.py`'s `run_source`), and profile its
    decisions across the kerbs of `site`, the truth in the world's `frame` or carried into the reconstruction's
    `own` (`cama_pipeline.evaluate.frame`: the SfM frame's placement taken out)."""
    with captured_decisions() as kept:
        row = run_source(site, poses, config, scratch, masks)
    grid, seen, label = kept["grid"], kept["seen"], kept["label"]
    xy = grid.vertex_xy()
    georeference = RasterGeoreference(
        origin_xy=grid.origin_xy, resolution=grid.resolution_m, width=grid.cols, height=grid.rows
    )
    # at the stage's own cell centres, as bench/surface.py scores; in the reconstruction's frame when asked
    world_of = None
    if frame == "own":
        world_of = reconstruction_frame(
            site / "nuscenes", Workspace(Path(row["workspace"])), row["site_id"]
        ).world_of
    truth = truth_on_grid(site, georeference, world_of)
    scored = row if frame == "world" else row["in_reconstruction_frame"]
    inside, rows, cols = nearest_true_cells(xy, truth)
    true_class = truth.require("semantic")[rows, cols]
    distance = signed_edge_distance(truth)[rows, cols]
    # the cells the rasters call observed (`outputs.rasters_from_vertices`: the ray count rounds to 1 or more)
    use = kept["observed"] & inside & (np.abs(distance) < max_distance_m) & (true_class != 255)
    road_level = np.zeros((len(xy), len(BEV_CLASSES)))
    curb_height = np.zeros_like(road_level)
    road_level[seen], curb_height[seen] = kept["road_level"], kept["curb_height"]
    edges = np.round(np.arange(-max_distance_m, max_distance_m + BIN_M / 2, BIN_M), 3)
    at_true_height = true_height_labels(true_class[use], road_level[use], curb_height[use])
    return {
        "poses": poses,
        "masks": row["masks"],
        "frame": frame,
        "kerb_band_m": config.kerb_step.kerb_band_m,
        "kerb_line": config.kerb_step.kerb_line,
        "iou": scored["iou"],
        "curb_confusion": scored["curb_confusion"],
        "band_iou": {
            "stage": band_iou(label[use], true_class[use]),
            "at_true_height": band_iou(at_true_height, true_class[use]),
        },
        "bins": profile(
            distance[use],
            true_class[use],
            road_level[use],
            curb_height[use],
            kept["score"][use],
            kept["raised"][use],
            label[use],
            edges,
        ),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--site", type=Path, default=Path("data/synthetic/default"))
    parser.add_argument("--sources", default="ground_truth,sfm")
    parser.add_argument("--max-distance", type=float, default=0.8, help="metres either side of the road edge")
    parser.add_argument(
        "--kerb-band", type=float, default=None, help="kerb_step.kerb_band_m (default: the stage's)"
    )
    parser.add_argument("--kerb-line", choices=("on", "off"), default=None, help="kerb_step.kerb_line")
    parser.add_argument(
        "--masks",
        default="auto",
        help="the masks the stage observes through: its own --masks choices, or generator (a mask-free site's)",
    )
    parser.add_argument(
        "--frame",
        choices=("world", "own"),
        default="world",
        help="the truth in the world's frame, or carried into the reconstruction's own",
    )
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--out", type=Path, default=RESULTS / "kerb_profile.json")
    args = parser.parse_args()
    config = SurfaceConfig(torch_threads=args.threads)
    if args.kerb_band is not None:
        config = replace(config, kerb_step=replace(config.kerb_step, kerb_band_m=args.kerb_band))
    if args.kerb_line is not None:
        config = replace(config, kerb_step=replace(config.kerb_step, kerb_line=args.kerb_line == "on"))
    scratch = Path(tempfile.mkdtemp(prefix="bench-kerb-profile-"))
    runs = {}
    try:
        for poses in args.sources.split(","):
            runs[poses] = source_profile(
                args.site, poses, config, scratch, args.max_distance, args.masks, args.frame
            )
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    for poses, run in runs.items():
        band = run["band_iou"]
        print(
            f"{poses}: curb IoU {run['iou']['curb']:.3f}; near the kerbs curb IoU {band['stage']['curb']:.3f}, "
            f"{band['at_true_height']['curb']:.3f} at the true heights"
        )
        print(
            "  from   cells curb | road level r/c/b | curb height r/c/b | score raised | right, at true height"
        )
        for b in run["bins"]:
            g, r = b["road_level_shares"], b["curb_height_shares"]
            print(
                f"  {b['from_m']:+.1f} {b['cells']:7d} {b['true_curb_share']:.2f} | "
                f"{g['road']:.2f} {g['curb']:.2f} {g['background']:.2f} | "
                f"{r['road']:.2f} {r['curb']:.2f} {r['background']:.2f} | "
                f"{b['median_score']:+.2f} {b['raised_share']:.2f} | {b['right']:.2f}, {b['right_at_true_height']:.2f}"
            )
    atomic_write_json(
        args.out,
        {
            "command": " ".join([sys.executable.split("/")[-1], *sys.argv]),
            "site": str(args.site),
            "machine": {"platform": platform.platform(), "torch": torch.__version__},
            "bin_m": BIN_M,
            "runs": runs,
        },
        indent=1,
    )
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
