"""How much of the annotator's time and of the road's height error at range is the images' resolution: the same
layouts built at two image sizes, side by side in one run.

The held-out reconstructions of the VMA figures are tiny randomised sites, rendered at 256x144 (the `tiny`
preset); nuScenes' cameras give 1600x900. At 256x144 a pixel 13 m away covers about 10 cm across the ray and
most of a metre along the ground, so the multi-view refinement finds nothing to agree on there and the road
stands centimetres too high at range ("Where the height error grows", README), which moves kerbs and far dividers
towards the cameras. Each `--pair LOW,HIGH` is one layout (the same generator seed, checked by layout digest)
built twice with `cama synth --image-size` and `cama run`; for each build the promoted element-mask network
proposes with the product's settings and is scored as the VMA benches score it (`reconstructed_figures`: Chamfer
mAP on the observed truth, the scripted annotator's correction and speed-up), and the road's height error is
split by distance from the camera track (`bench/surface_range.py`'s `reconstruction_errors`). The higher
resolution's saving is given with the gate's confidence (`saving_confidence`) over the pairs. The checkpoint is
refused on any site it saw.

Usage: .venv/bin/python bench/image_resolution.py --pair data/synthetic/random-9221,data/synthetic/random512-9221
       [--pair ...] [--checkpoint models/vma/element_masks/checkpoints] [--threads 2]
       [--out bench/results/image_resolution.json]
"""

import argparse
import json
import platform
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch
from scipy.spatial import cKDTree

from cama_pipeline.bev import read_bev
from cama_pipeline.io import atomic_write_json
from cama_pipeline.site_identity import SeenSiteError, site_identity
from models.vma.element_masks.net import ElementMaskNet
from models.vma.element_masks.propose import product_proposer
from models.vma.validation import ValidationSite, reconstruction_of

# the shared conditions: `bench` is a package at the repository root
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from bench.paired_saving import saving_figures  # noqa: E402
from bench.surface_range import band_figures, camera_track, reconstruction_errors  # noqa: E402
from bench.vma_measures import reconstructed_figures, unseen_mask_checkpoint  # noqa: E402

RESULTS = Path(__file__).parent / "results"
BUILDS = ("low", "high")


class PairError(ValueError):
    """Two builds that are not the same layout at two image sizes (named in the message)."""


def image_size(site: Path) -> tuple[int, int]:
    """(width, height) of the images a synthetic site was rendered at, from its manifest's camera config."""
    manifest = json.loads((site / "manifest.json").read_text(encoding="utf-8"))
    camera = manifest["config"]["camera"]
    return int(camera["width_px"]), int(camera["height_px"])


def checked_pair(low: Path, high: Path) -> dict[str, Any]:
    """The pair's identity: one layout (same digest) at two image sizes, the first the smaller."""
    layouts = [site_identity(site).layout_digest for site in (low, high)]
    if layouts[0] != layouts[1]:
        raise PairError(f"{low} and {high} are different layouts ({layouts[0]} against {layouts[1]})")
    sizes = [image_size(site) for site in (low, high)]
    if sizes[0][0] * sizes[0][1] >= sizes[1][0] * sizes[1][1]:
        raise PairError(f"{low} ({sizes[0]}) is not rendered smaller than {high} ({sizes[1]})")
    return {"layout_digest": layouts[0], "sites": [str(low), str(high)], "image_sizes": sizes}


def height_errors(sites: list[ValidationSite]) -> list[dict[str, Any]]:
    """The road's height error by distance from the camera track, pooled over `sites` (each surface's offset near
    the track taken out, as `bench/surface_range.py` does)."""
    distances, errors = [], []
    for site in sites:
        truth = read_bev(site.site / "ground_truth" / "bev", ("semantic", "elevation"))
        positions, _ = camera_track(site.site)
        distance, error = reconstruction_errors(site.site, truth, cKDTree(positions))
        distances.append(distance)
        errors.append(error)
    return band_figures(np.concatenate(distances), np.concatenate(errors))


def measure(pairs: list[tuple[Path, Path]], model: ElementMaskNet) -> dict[str, Any]:
    """Both builds of every pair, and the higher resolution's saving over the pairs."""
    propose = product_proposer(model)
    figures: dict[str, Any] = {}
    for index, build in enumerate(BUILDS):
        sites = [reconstruction_of(pair[index]) for pair in pairs]
        scored = reconstructed_figures(propose, sites)
        figures[build] = {
            "image_sizes": sorted({f"{w}x{h}" for w, h in (image_size(pair[index]) for pair in pairs)}),
            "observed_truth_map": scored["observed_truth"]["mean_ap"],
            "class_ap": scored["observed_truth"]["class_ap"],
            "annotator": scored["annotator"],
            "height_error_by_distance": height_errors(sites),
        }
        annotator = scored["annotator"]
        print(
            f"{build}: mAP {scored['observed_truth']['mean_ap']:.3f}, {annotator['correction_s']:.1f} s of "
            f"correction ({annotator['speed_up']:.2f}x)",
            flush=True,
        )
    low, high = (figures[b]["annotator"]["per_site_correction_s"] for b in BUILDS)
    saving = saving_figures(low, high)
    figures["high_against_low"] = {
        "correction_ratio": sum(high) / sum(low),
        "speed_up_gain": figures["high"]["annotator"]["speed_up"] - figures["low"]["annotator"]["speed_up"],
        "saving_confidence": saving["saving_confidence"],
        "faster_pairs": saving["faster_sites"],
        "slower_pairs": saving["slower_sites"],
    }
    return figures


def parse_pair(text: str) -> tuple[Path, Path]:
    """`LOW,HIGH` -> the two site folders."""
    parts = text.split(",")
    if len(parts) != 2 or not all(parts):
        raise argparse.ArgumentTypeError(f"--pair {text!r}: expected LOW_SITE,HIGH_SITE")
    return Path(parts[0]), Path(parts[1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--pair", type=parse_pair, action="append", required=True)
    parser.add_argument("--checkpoint", type=Path, default=Path("models/vma/element_masks/checkpoints"))
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--out", type=Path, default=RESULTS / "image_resolution.json")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    try:
        identities = [checked_pair(low, high) for low, high in args.pair]
        checkpoint = unseen_mask_checkpoint(args.checkpoint, [site for pair in args.pair for site in pair])
    except (ValueError, SeenSiteError, OSError, KeyError) as error:
        parser.exit(2, f"image_resolution: {error}\n")
    started = time.perf_counter()
    figures = measure(args.pair, checkpoint.model)
    report = {
        "command": "python bench/image_resolution.py "
        + "".join(f"--pair {low},{high} " for low, high in args.pair)
        + f"--checkpoint {args.checkpoint} --threads {args.threads}",
        "checkpoint": str(checkpoint.path),
        "pairs": identities,
        **figures,
        "machine": {"cpu_threads": args.threads, "platform": platform.platform(), "device": "cpu"},
        "seconds": round(time.perf_counter() - started, 1),
    }
    atomic_write_json(args.out, report)
    print(f"written to {args.out}")


if __name__ == "__main__":
    main()
