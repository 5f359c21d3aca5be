"""Train the segmenter on a many-core machine with a GPU, to a deadline: make the training sites on every core,
then train for the time that is left, with the crops made by loader workers.

The lent GPU machines give a session minutes, not hours, and start bare: the sites are rendered there
(`segmenter_sites.training_site_config`, one site per process) and the training fills whatever of the deadline the
rendering and loading leave (`TrainConfig.time_budget_s`). The runs that made `gpu-long` and the shipped
`gpu-long2` (README, "Training on a GPU"), with the wheels of shapely and pydantic carried there and
`OMP_NUM_THREADS=1`; the second ran on the same machine, with `gpu-long` carried to `.ckpt/gpu-long`:

    python3 bench/segmenter_gpu.py --work /tmp/seg --seeds 100-119,123-179 --init cama_pipeline/segment/shipped \\
        --out $OUT/gpu-long --label gpu-long --finish-within 510
    python3 bench/segmenter_gpu.py --work /tmp/seg --seeds 100-119,123-179 --init .ckpt/gpu-long \\
        --out $OUT/gpu-long2 --label gpu-long2 --learning-rate 5e-4 --finish-within 215

It writes the checkpoint and, beside it, `gpu_run.json` (`run_report`): the seconds of every phase, the machine,
the steps and the checkpoint's lineage. The two runs of `gpu-long` and `gpu-long2` are in
`bench/results/segmenter_gpu_runs.json` (their reports, written before `run_report` also recorded the lineage, with
it filled in from the checkpoints they returned).
"""

import argparse
import json
import logging
import os
import sys
import time
from pathlib import Path
from typing import Any

import torch
from segmenter_sites import (  # bench/segmenter_sites.py: this script's folder is on sys.path
    make_sites,
    parse_seeds,
)

from cama_pipeline.segment.config import TrainConfig
from cama_pipeline.segment.predict import resolve_device
from cama_pipeline.segment.train import train

LOAD_AND_SCORE_RESERVE_S = 60.0
"""Seconds kept from the deadline for what `train` does around the training itself: decoding every training
image (about 1.5 ms each), scoring the held-out site and saving."""


def run_report(meta: dict[str, Any], sites_s: float, total_s: float) -> dict[str, Any]:
    """What a run did, from its checkpoint record: the seconds of each phase, the machine, the steps and passes,
    the held-out IoU, and the checkpoint with the one it went on from (label and weights digest)."""
    parent = meta.get("parent") or {}
    return {
        "label": meta["label"],
        "weights_sha256": meta["weights_sha256"],
        "parent": {"label": parent.get("label"), "weights_sha256": parent.get("weights_sha256")},
        "train": meta["train"],
        "training_seeds": sorted(site["seed"] for site in meta["training_sites"]),
        "sites_seconds": round(sites_s, 1),
        "train_call_seconds": meta["seconds"],
        "total_seconds": round(total_s, 1),
        "device": meta["device"],
        "cpu_count": os.cpu_count(),
        "torch": torch.__version__,
        "steps": meta["metrics"]["steps"],
        "passes": meta["epochs"],
        "crops_per_second": meta["metrics"]["crops_per_second"],
        "held_out": meta["metrics"].get("held_out", {}).get("per_class_iou"),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--work", type=Path, required=True, help="folder for the generated sites")
    parser.add_argument(
        "--seeds", type=parse_seeds, required=True, help="training sites, e.g. 100-119,123-199"
    )
    parser.add_argument(
        "--held-out-seed", type=int, default=9001, help="a measurement seed scored after training"
    )
    parser.add_argument("--init", type=Path, help="checkpoint to go on from")
    parser.add_argument("--out", type=Path, required=True, help="checkpoint folder to write")
    parser.add_argument("--label")
    parser.add_argument(
        "--finish-within", type=float, required=True, help="seconds from start to the checkpoint"
    )
    parser.add_argument("--processes", type=int, default=os.cpu_count() or 1, help="sites rendered at a time")
    parser.add_argument("--loader-workers", type=int, default=max(1, (os.cpu_count() or 2) - 2))
    parser.add_argument("--batch-size", type=int, default=16)
    parser.add_argument("--crop", type=int, nargs=2, default=(288, 512), metavar=("HEIGHT", "WIDTH"))
    parser.add_argument("--learning-rate", type=float, default=1e-3)
    parser.add_argument("--max-class-weight", type=float, default=2.0)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--device", default="auto")
    args = parser.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(message)s")
    started = time.perf_counter()
    make_sites(args.seeds, args.work / "train", processes=args.processes)
    make_sites([args.held_out_seed], args.work / "held-out")
    sites_s = time.perf_counter() - started
    budget = args.finish_within - sites_s - LOAD_AND_SCORE_RESERVE_S
    if budget < 30:
        raise SystemExit(f"rendering the sites took {sites_s:.0f} s: too little of --finish-within is left")
    print(f"sites made in {sites_s:.0f} s; training for {budget:.0f} s", flush=True)
    config = TrainConfig(
        batch_size=args.batch_size,
        crop_height_px=args.crop[0],
        crop_width_px=args.crop[1],
        learning_rate=args.learning_rate,
        max_class_weight=args.max_class_weight,
        seed=args.seed,
        threads=2,
        loader_workers=args.loader_workers,
        time_budget_s=budget,
    )
    folder = train(
        config,
        [args.work / "train"],
        args.out,
        held_out=[args.work / "held-out" / f"r{args.held_out_seed}"],
        init=args.init,
        device=resolve_device(args.device),
        label=args.label,
        show_progress=False,
    )
    meta = json.loads((folder / "checkpoint.json").read_text(encoding="utf-8"))
    report = run_report(meta, sites_s, time.perf_counter() - started)
    report["command"] = " ".join(["python3", *sys.argv])
    (folder.parent / "gpu_run.json").write_text(json.dumps(report, indent=2) + "\n", encoding="utf-8")
    print(json.dumps(report, indent=2), flush=True)


if __name__ == "__main__":
    main()
