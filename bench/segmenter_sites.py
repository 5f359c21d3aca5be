"""The sites the shipped segmenter was trained and held out on, so its training can be repeated from the repo.

Randomised tiny sites (`cama_pipeline.synthetic.randomise`) rendered at 512x288 with key frames only (sweeps at the
sample rate) and 2.5 s moving clips: many layouts and looks for little rendering time. The shipped checkpoint
(`cama_pipeline/segment/shipped/checkpoint.json` lists every site it saw) trained first on seeds 100-111 and held
out seed 9001 (a measurement seed, which `cama train-segmenter` refuses to train on):

    .venv/bin/python bench/segmenter_sites.py --out data/segmenter/train --seeds 100-111
    .venv/bin/python bench/segmenter_sites.py --out data/segmenter/held-out --seeds 9001
    .venv/bin/cama train-segmenter --sites data/segmenter/train --held-out data/segmenter/held-out/r9001 \
        --out data/segmenter/checkpoint --epochs 22 --scale-range 0.7 1.3

`shipped-v3` is `shipped-v2` calibrated (`cama calibrate-segmenter`: one logit offset per class) on seeds 120-122,
which it never trained on (its checkpoint.json records v2 as its parent and these sites among those it saw):

    .venv/bin/python bench/segmenter_sites.py --out data/segmenter/calibrate --seeds 120-122
    .venv/bin/cama calibrate-segmenter --sites data/segmenter/calibrate --checkpoint <shipped-v2> \
        --out data/segmenter/ckpt/shipped-v3 --label shipped-v3

`refined-cap2` is `shipped-v2` gone on with the full-resolution refinement (README, "Full-resolution
refinement"), on the same training sites; `<shipped-v2>` is a folder with `shipped-v2`'s `model.pt` and
`checkpoint.json` as they were at commit 3e376aa (`git show 3e376aa:cama_pipeline/segment/shipped/model.pt`);
`refined-cap2` itself is at commit ce3738d:

    .venv/bin/cama train-segmenter --sites data/segmenter/train --held-out data/synthetic/tiny-random-9001 \
        --out data/segmenter/ckpt/refined-cap2 --init <shipped-v2> --full-resolution-width 12 \
        --max-class-weight 2 --epochs 16 --learning-rate 1e-3 --threads 1 --seed 7 --scale-range 0.7 1.3

The shipped `refined-scale1` is `refined-cap2` gone on for 8 epochs on 24 sites (seeds 100-119 and 123-126;
120-122 are the calibration sites) with every image at its own scale, so no mask is resampled (README, "Training
at the images' own scale"); the earlier checkpoints were trained with `--scale-range 0.7 1.3`, the default then:

    .venv/bin/python bench/segmenter_sites.py --out data/segmenter/train --seeds 112-119
    .venv/bin/python bench/segmenter_sites.py --out data/segmenter/train --seeds 123-126
    .venv/bin/cama train-segmenter --sites data/segmenter/train --held-out data/synthetic/tiny-random-9001 \
        --out data/segmenter/ckpt/refined-scale1 --init data/segmenter/ckpt/refined-cap2 \
        --full-resolution-width 12 --max-class-weight 2 --epochs 8 --learning-rate 5e-4 --threads 1 --seed 9 \
        --scale-range 1 1 --label refined-scale1   # (1, 1) is the default now

The shipped `scale1-more` is `refined-scale1` gone on for 4 epochs on 38 sites (the 24 above and seeds 127-140),
seed 11; `scale1-fade` is the same run with extra paint fade (`--paint-fade-max 0.4`), which did not help (README,
"More sites, and extra paint fade"):

    .venv/bin/python bench/segmenter_sites.py --out data/segmenter/train --seeds 127-140
    .venv/bin/cama train-segmenter --sites data/segmenter/train --held-out data/synthetic/tiny-random-9001 \
        --out data/segmenter/ckpt/scale1-more --init data/segmenter/ckpt/refined-scale1 \
        --full-resolution-width 12 --max-class-weight 2 --epochs 4 --learning-rate 5e-4 --threads 1 --seed 11 \
        --scale-range 1 1 --label scale1-more   # --out .../scale1-fade --label scale1-fade --paint-fade-max 0.4

`scale1-rescale` is `scale1-more`'s run with the training masks resampled like the images (`train.resize_labels`)
and a rescale: `--out data/segmenter/ckpt/scale1-rescale --label scale1-rescale --scale-range 0.7 1.3 --threads 2`.

Each site goes to `<out>/r<seed>`; a site already there and up to date is skipped (the generator's own check).
"""

import argparse
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from pathlib import Path

from cama_pipeline.synthetic.config import SynthConfig
from cama_pipeline.synthetic.generate import run
from cama_pipeline.synthetic.randomise import randomised_config


def training_site_config(seed: int) -> SynthConfig:
    """Randomised tiny site `seed` at 512x288, key frames only, 2.5 s moving clips."""
    cfg = randomised_config(seed, base="tiny")
    return replace(
        cfg,
        camera=replace(cfg.camera, width_px=512, height_px=288),
        clips=replace(cfg.clips, sweep_hz=cfg.clips.sample_hz, moving_duration_s=2.5),
    )


def parse_seeds(text: str) -> list[int]:
    """`100-111` or `100,105,9001` (or both, comma separated) as a list of seeds."""
    seeds: list[int] = []
    for part in text.split(","):
        first, _, last = part.strip().partition("-")
        seeds += list(range(int(first), int(last or first) + 1))
    return seeds


def make_site(seed: int, out: Path, workers: int = 1) -> str:
    """Site `seed` generated into `out/r<seed>` (skipped when up to date); a line saying how long it took."""
    started = time.perf_counter()
    result = run(training_site_config(seed), out / f"r{seed}", workers=workers, show_progress=False)
    return f"seed {seed}: {result.images} images in {time.perf_counter() - started:.0f} s"


def make_sites(seeds: list[int], out: Path, *, workers: int = 1, processes: int = 1) -> None:
    """Every site of `seeds` into `out`: one after another with `workers` render workers each, or `processes`
    sites at a time with one each (a many-core machine)."""
    if processes <= 1:
        for seed in seeds:
            print(make_site(seed, out, workers), flush=True)
        return
    with ProcessPoolExecutor(processes) as pool:
        for line in pool.map(make_site, seeds, [out] * len(seeds)):
            print(line, flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True, help="folder for the sites (r<seed> each)")
    parser.add_argument("--seeds", type=parse_seeds, required=True, help="e.g. 100-111 or 9001")
    parser.add_argument("--workers", type=int, default=1, help="render workers of each site")
    parser.add_argument("--processes", type=int, default=1, help="sites made at a time (one worker each)")
    args = parser.parse_args()
    make_sites(args.seeds, args.out, workers=args.workers, processes=args.processes)


if __name__ == "__main__":
    main()
