"""The surface stage with its settings changed, each variant against the first, on several sites in one run.

Each variant is the shipped `SurfaceConfig` with some fields set (`NAME=JSON`: its fields, and those of its parts
as nested objects, e.g. `'smooth 30={"refine": {"smoothness_weight": 30}}'`). Every variant runs the surface stage
with the site's SfM poses, as the product does (`bench/surface.py`'s `run_source`: a fresh workspace sharing the
site's sites, SfM and masks), all in one run per site, and is scored as `bench/surface.py` scores a run: the road's
elevation RMSE (and by distance from the trajectory), the class IoU against the truth in the world's frame and in the
reconstruction's own, PSNR, seconds. The first variant is the baseline the others are compared with (default: the
shipped settings, `shipped={}`). A variant's JSON may also name the masks the stage observes through, `"masks"`:
`auto` (the default: the data set's, else the workspace's), `predicted`, `imported`, `dataset`, or `generator`
(a mask-free site's generator masks, kept in its `ground_truth/` for evaluation), so the same SfM run with the
segmenter's masks and with the generator's splits what the masks cost the surface from what the rest does.
`bench/surface_gate.py` runs its SfM gate variants through the same loop.

Usage: .venv/bin/python bench/surface_variants.py --site SITE [--site SITE ...] [--variant NAME=JSON ...]
       [--threads 2] [--out bench/results/surface_variants.json]
"""

import argparse
import json
import platform
import shutil
import sys
import tempfile
from pathlib import Path
from typing import Any

import torch

from cama_pipeline.io import atomic_write_json
from cama_pipeline.surface import SurfaceConfig
from cama_studio.config import ConfigError, from_table

RESULTS = Path(__file__).parent / "results"
CLASSES = ("road", "curb", "lane_marking", "crosswalk")
MASKS = ("auto", "predicted", "imported", "dataset", "generator")
"""What a variant's `"masks"` may name (module docstring)."""


def parse_variant(text: str, threads: int) -> tuple[str, SurfaceConfig, dict[str, Any]]:
    """`NAME=JSON` -> (name, the shipped config on `threads` torch threads with the JSON's fields set, as a run
    configuration's `[surface]` table sets them: `cama_studio.config.from_table`, the JSON, whose `"masks"` is
    not a setting but the masks to observe through, `MASKS`); SystemExit naming the text when malformed, or the
    key the configuration refuses."""
    name, separator, values = text.partition("=")
    try:
        overrides = json.loads(values) if separator else None
    except json.JSONDecodeError as error:
        raise SystemExit(f"--variant {text!r}: not NAME=JSON ({error})") from None
    if not name or not isinstance(overrides, dict):
        raise SystemExit(
            f'--variant {text!r}: expected NAME=JSON, e.g. \'smooth={{"refine": {{"smoothness_weight": 30}}}}\''
        )
    masks = overrides.get("masks", "auto")
    if masks not in MASKS:
        raise SystemExit(f"--variant {name!r}: masks {masks!r} is not one of {', '.join(MASKS)}")
    settings = {key: value for key, value in overrides.items() if key != "masks"}
    try:
        config = from_table(
            SurfaceConfig, {"torch_threads": threads, **settings}, source=f"--variant {name!r}"
        )
    except ConfigError as error:
        raise SystemExit(str(error)) from None
    return name, config, overrides


def figures(run: dict[str, Any]) -> dict[str, Any]:
    """What the comparison reads of a `run_source` result."""
    return {
        "elevation_rmse_cm": run["elevation_rmse_m"] * 100,
        "elevation_rmse_cm_by_distance_m": {
            span: value * 100 for span, value in run["elevation_rmse_m_by_distance_from_trajectory_m"].items()
        },
        "iou": run["iou"],
        "iou_in_reconstruction_frame": run["in_reconstruction_frame"]["iou"],
        "psnr_db": run["psnr_db"],
        "sfm_points_kept": run["points"].get("sfm_kept"),
        "extrapolated_heights": run["extrapolated_heights"],
        "height_error_by_support": run["height_error_by_support"],
        "seconds": run["seconds"]["total"],
    }


def against_baseline(runs: dict[str, Any]) -> dict[str, Any]:
    """Each run's elevation, own-frame IoU and seconds against the first run's."""
    baseline = next(iter(runs.values()))
    return {
        name: {
            "elevation_rmse_cm": run["elevation_rmse_cm"] - baseline["elevation_rmse_cm"],
            "iou_in_reconstruction_frame": {
                c: v - baseline["iou_in_reconstruction_frame"][c]
                for c, v in run["iou_in_reconstruction_frame"].items()
            },
            "psnr_db": run["psnr_db"] - baseline["psnr_db"],
            "seconds_ratio": run["seconds"] / max(baseline["seconds"], 1e-9),
        }
        for name, run in runs.items()
    }


def run_variants(
    sites: list[Path], variants: list[tuple[str, SurfaceConfig, dict[str, Any]]]
) -> dict[str, Any]:
    """Every variant on every site with SfM poses: {site: {"runs": {name: settings + figures}, "against_baseline"}}."""
    from surface import run_source  # bench/surface.py, on sys.path when this runs as a script

    results: dict[str, Any] = {}
    for site in sites:
        runs: dict[str, Any] = {}
        for name, config, settings in variants:
            scratch = Path(tempfile.mkdtemp(prefix="bench-surface-variants-"))
            try:
                masks = settings.get("masks", "auto")
                runs[name] = {**settings, **figures(run_source(site, "sfm", config, scratch, masks))}
            finally:
                shutil.rmtree(scratch, ignore_errors=True)
            own = runs[name]["iou_in_reconstruction_frame"]
            print(
                f"{site.name} {name}: elevation {runs[name]['elevation_rmse_cm']:.2f} cm, own frame IoU "
                + " / ".join(f"{own[c]:.3f}" for c in CLASSES)
                + f", {runs[name]['seconds']:.0f} s",
                flush=True,
            )
        results[str(site)] = {"runs": runs, "against_baseline": against_baseline(runs)}
    return results


def write_results(path: Path, sites: dict[str, Any], threads: int) -> None:
    results = {
        "command": " ".join([sys.executable.split("/")[-1], *sys.argv]),
        "poses": "sfm",
        "machine": {"platform": platform.platform(), "torch": torch.__version__, "threads": threads},
        "sites": sites,
    }
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_json(path, results, indent=1)
    print(f"wrote {path}")


def parse_arguments(description: str, variant_form: str, out: Path) -> argparse.Namespace:
    """The command line of a variants bench: --site (repeatable), --variant in `variant_form`, --threads, --out."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--site", type=Path, action="append", required=True, help="a site with its SfM run")
    parser.add_argument("--variant", action="append", default=None, help=f"{variant_form} (repeatable)")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--out", type=Path, default=out)
    return parser.parse_args()


def main() -> None:
    args = parse_arguments(__doc__.splitlines()[0], "NAME=JSON", RESULTS / "surface_variants.json")
    variants = [parse_variant(text, args.threads) for text in (args.variant or ["shipped={}"])]
    write_results(args.out, run_variants(args.site, variants), args.threads)


if __name__ == "__main__":
    main()
