"""Helpers of the generator tests: a micro config that generates in seconds, and file digests to compare."""

import hashlib
from dataclasses import replace
from pathlib import Path

from cama_pipeline.synthetic.config import ClipConfig, SynthConfig, preset


def micro_config(seed: int = 7) -> SynthConfig:
    """The tiny preset cut to one short moving clip (plus the stationary and night clips)."""
    clips = ClipConfig(
        moving_duration_s=1.1,
        stationary_duration_s=0.6,
        night_duration_s=0.6,
        routes=("east",),
        moving_vehicles_per_clip=2,
    )
    return replace(preset("tiny", seed=seed), clips=clips)


def file_digests(root: Path) -> dict[str, str]:
    """sha256 of every file under `root` but the manifest (which holds timings), by relative path."""
    return {
        str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(root.rglob("*"))
        if p.is_file() and p.name != "manifest.json"
    }
