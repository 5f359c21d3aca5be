"""A training site and a segmenter trained on it for a few steps, for the segment tests (seconds, not minutes).

The training site is a copy of the tiny site whose generator manifest names it as another place (seed, layout
and location of its own): training refuses the tiny site itself, a measurement site, and the tests need a site
it may train on without rendering a second one."""

import json
import shutil
from dataclasses import replace
from pathlib import Path

from cama_pipeline.segment.config import NetworkConfig, TrainConfig
from cama_pipeline.segment.train import train

TRAINING_SEED = 4242
SMALL_NETWORK = NetworkConfig(widths=(8, 8, 16, 16, 16), input_width_px=256)
FEW_STEPS = TrainConfig(
    epochs=1, batch_size=2, images_per_epoch=4, crop_height_px=64, crop_width_px=96, threads=1
)


def relabelled_copy(
    site: Path, out: Path, seed: int = TRAINING_SEED, lane_width_shift_m: float = 0.25
) -> Path:
    """A copy of a generated site whose manifest gives it seed `seed`, a location and a layout of its own (lanes
    `lane_width_shift_m` wider: copies made with different shifts are different layouts)."""
    shutil.copytree(site, out)
    manifest = json.loads((out / "manifest.json").read_text(encoding="utf-8"))
    manifest["seed"] = manifest["config"]["seed"] = seed
    manifest["config"]["location"] = f"test-copy-{seed}"
    manifest["config"]["layout"]["lane_width_m"] += lane_width_shift_m
    (out / "manifest.json").write_text(json.dumps(manifest), encoding="utf-8")
    return out


def train_small(training_site: Path, out: Path, seed: int = 0) -> Path:
    """A checkpoint of the small network trained for two steps on `training_site`."""
    return train(
        replace(FEW_STEPS, seed=seed), [training_site], out, network=SMALL_NETWORK, show_progress=False
    )
