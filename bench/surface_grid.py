"""The grid's own ceiling on the surface's class IoUs: what an observer that saw the paint perfectly would score.

The truth raster labels each 0.1 m cell by the paint at its centre (the generator samples its ground atlas there).
A camera sees a cell as an area, never as its centre, so even a perfect observer that labelled every cell by the
larger share of its area would disagree with the truth wherever paint covers part of a cell: a 0.15 m lane line
covers one or two cells whole and the cells beside it in part. For each site the generator's world is rebuilt from
the site's manifest (preset, seed and random seed), checked against the stored truth (its cell-centre labels must be
`ground_truth/bev/semantic.png` wherever that is observed, else the site is refused), and sampled `--samples`^2
times in every cell. Per class: the IoU of the area-majority labels against the truth (the ceiling of any observer
that labels a cell by the class covering more than half of it), and how many cells, among the true cells of the class and their 4-neighbours, the class
covers by 30-70 % of their area: cells whose label a shift of the paint's edge by a centimetre or two decides.

`bench/surface_split.py` splits the stage's error down to the true surface; this is the floor under that.

Usage: .venv/bin/python bench/surface_grid.py [--site DIR ...] [--samples 4] [--out bench/results/surface_grid.json]
"""

import argparse
import platform
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
from scipy import ndimage

from cama_pipeline.io import atomic_write_json
from cama_pipeline.semantics import Semantic
from cama_pipeline.synthetic import ground_truth
from cama_pipeline.synthetic.truth_grid import centre_labels, rebuilt_world, stored_truth

RESULTS = Path(__file__).parent / "results"
CLASSES = {"curb": Semantic.CURB, "lane_marking": Semantic.LANE_MARKING, "crosswalk": Semantic.CROSSWALK}
UNDECIDED = (0.3, 0.7)
"""Area shares of a class in a cell that a centimetre or two of the paint's edge moves across one half."""


def cell_labels(site: Path, samples: int) -> tuple[np.ndarray, np.ndarray]:
    """The stored true semantic raster and the (classes, rows, cols) shares of each class in every cell's area;
    TruthMismatch (a ValueError) when the world rebuilt from the manifest does not give the stored truth at the
    cell centres."""
    truth = stored_truth(site)
    cfg, world = rebuilt_world(site, truth)
    grid = ground_truth.bev_grid_for(world, cfg.bev_resolution_m)
    semantic = truth.require("semantic")
    offsets = ((np.arange(samples) + 0.5) / samples - 0.5) * cfg.bev_resolution_m
    shares = np.zeros((int(max(Semantic)) + 1, grid.rows, grid.cols), np.float32)
    for dy in offsets:
        for dx in offsets:
            label = centre_labels(world, grid, float(dx), float(dy))
            for cls in CLASSES.values():
                shares[int(cls)] += label == int(cls)
    return semantic, shares / samples**2


def ceiling(site: Path, samples: int) -> dict[str, Any]:
    """The site's per-class figures (see the module docstring)."""
    started = time.perf_counter()
    truth, shares = cell_labels(site, samples)
    observed = truth != 255
    classes = {}
    for name, cls in CLASSES.items():
        share = shares[int(cls)]
        area, true = observed & (share > 0.5), observed & (truth == int(cls))
        near = observed & ndimage.binary_dilation(true)
        undecided = near & (share >= UNDECIDED[0]) & (share <= UNDECIDED[1])
        classes[name] = {
            "area_rule_iou": float((area & true).sum() / max((area | true).sum(), 1)),
            "true_cells": int(true.sum()),
            "undecided_cells": int(undecided.sum()),
            "undecided_per_true_cell": float(undecided.sum() / max(true.sum(), 1)),
        }
    return {"site": str(site), "classes": classes, "seconds": round(time.perf_counter() - started, 1)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--site", type=Path, action="append", help="a synthetic site (repeat); default: default"
    )
    parser.add_argument("--samples", type=int, default=4, help="samples per cell along each axis")
    parser.add_argument("--out", type=Path, default=RESULTS / "surface_grid.json")
    args = parser.parse_args()
    if args.samples < 2:
        parser.error(f"--samples must be >= 2, got {args.samples}")
    sites = args.site or [Path("data/synthetic/default")]
    rows = []
    for site in sites:
        row = ceiling(site, args.samples)
        rows.append(row)
        figures = ", ".join(
            f"{name} {c['area_rule_iou']:.3f} ({c['undecided_per_true_cell']:.2f} undecided per true cell)"
            for name, c in row["classes"].items()
        )
        print(f"{site}: area-rule IoU {figures}", flush=True)
    atomic_write_json(
        args.out,
        {
            "command": " ".join(["python", *sys.argv]),
            "samples_per_axis": args.samples,
            "undecided_shares": list(UNDECIDED),
            "machine": {"platform": platform.platform(), "python": platform.python_version()},
            "sites": rows,
        },
        indent=1,
    )
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
