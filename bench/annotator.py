"""Simulated-annotator benchmark: person-hours per km of road to draw a site from scratch vs to correct proposals.

A scripted annotator (`app/simulation`) works the backend's annotator queue over the HTTP API of an in-process
backend (fresh SQLite database): it accepts proposals that match the ground truth, fixes the others towards it
(counting vertex drags, inserts, deletes and relabels), rejects the ones that match nothing, and draws what no
proposal covered. A second, empty copy of the site is drawn from scratch. Every action is priced with the
keystroke-level model (`app/review_effort/costs.py`); both workflows pay the same road-scanning time.

With `--rasters FOLDER` (a reconstruction's BEV rasters) the truth is cut to the cells they observed, as
`bench/end_to_end.py` does; without it the whole generated truth is the target. When the rasters are the surface
stage's of one of the site's reconstructions (`<workspace>/surface/<site id>/bev`), the truth is first carried
into that reconstruction's frame (`cama_pipeline.evaluate.frame`: an annotator sees the rasters, not the world;
recorded as `reconstruction_frame`); rasters from elsewhere leave it in the world's (`reconstruction_frame` null).

Usage: .venv/bin/python bench/annotator.py [--site data/synthetic/default] [--proposals FILE ...]
       [--rasters FOLDER] [--out bench/results/annotator.json]
Prints the figures and writes them to --out.
"""

import argparse
import json
import logging
import platform
import sys
import time
from pathlib import Path
from typing import Any

from app.review_effort.truth import observed_true_polylines, true_polylines
from app.simulation.annotator import correct_proposals, draw_from_scratch
from app.simulation.workbench import load_proposals, local_backend, register_synthetic_site
from cama_pipeline.evaluate.frame import ReconstructionFrame, reconstruction_frame
from cama_pipeline.site.io import read_site_ids
from cama_pipeline.workspace import Workspace
from models.vma.rasters import load_site_rasters

RESULTS = Path(__file__).parent / "results" / "annotator.json"


def frame_of(site: Path, rasters: Path) -> ReconstructionFrame | None:
    """The frame of the reconstruction of `site` whose surface rasters `rasters` are (`<workspace>/surface/<site
    id>/bev`, any workspace); None when they are not a surface stage's."""
    folder = rasters.resolve()
    if len(folder.parents) < 3:
        return None
    workspace, site_id = Workspace(folder.parents[2]), folder.parent.name
    if workspace.surface_bev(site_id).resolve() != folder or not workspace.surface_report(site_id).is_file():
        return None
    return reconstruction_frame(site / "nuscenes", workspace, site_id)


def run(site: Path, proposal_files: list[Path], rasters: Path | None = None) -> dict[str, Any]:
    frame = frame_of(site, rasters) if rasters else None
    truths = (
        observed_true_polylines(site, load_site_rasters(rasters), frame) if rasters else true_polylines(site)
    )
    with local_backend(site) as (admin, annotator):
        started = time.perf_counter()
        scratch = draw_from_scratch(annotator, register_synthetic_site(admin, site, "scratch"), truths)
        out: dict[str, Any] = {"from_scratch": {**scratch.as_dict(), "wall_s": time.perf_counter() - started}}
        for path in proposal_files:
            site_id = register_synthetic_site(admin, site, f"proposals-{path.stem}")
            loaded = load_proposals(admin, site_id, path)
            started = time.perf_counter()
            log = correct_proposals(annotator, site_id, truths)
            out[str(path)] = {
                **log.as_dict(),
                "proposals": loaded,
                "wall_s": time.perf_counter() - started,
                "speed_up_vs_scratch": scratch.total_s / log.total_s if log.total_s else None,
            }
    truth = f"cut to the cells observed in {rasters}" if rasters else "all"
    return {
        "site": str(site),
        "truth": truth,
        "reconstruction_frame": frame.as_dict() if frame else None,
        "true_elements": len(truths),
        "results": out,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--site", type=Path, default=Path("data/synthetic/default"))
    parser.add_argument(
        "--proposals",
        type=Path,
        nargs="*",
        default=None,
        help="Default: the proposals `cama run` wrote for the site's first workspace site",
    )
    parser.add_argument(
        "--rasters", type=Path, default=None, help="cut the truth to these rasters' observed cells"
    )
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)
    workspace = Workspace.for_dataset(args.site / "nuscenes")
    files = args.proposals or [workspace.proposals(read_site_ids(workspace.sites_index())[0])]
    figures = run(args.site, files, args.rasters)
    figures["command"] = "python bench/annotator.py " + " ".join(sys.argv[1:])
    figures["machine"] = {"python": platform.python_version()}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(figures, indent=1))
    for name, result in figures["results"].items():
        speed = result.get("speed_up_vs_scratch")
        print(
            f"{name}: {result['hours_per_km']:.2f} person-h/km ({result['total_s'] / 60:.1f} min over {result['road_km']:.2f} km)"
            + (f", {speed:.2f}x faster than drawing" if speed else "")
            + f"  counts {dict(result['counts'])}"
        )
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
