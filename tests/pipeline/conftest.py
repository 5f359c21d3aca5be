"""Fixtures of the whole-run tests: a tiny site generated as real nuScenes is, once per session."""

import pytest

from cama_pipeline.synthetic.config import preset
from cama_pipeline.synthetic.generate import SynthResult
from cama_pipeline.synthetic.generate import run as synthesize


@pytest.fixture(scope="session")
def mask_free_site(tmp_path_factory: pytest.TempPathFactory) -> SynthResult:
    """The tiny preset as `cama synth --no-masks` writes it: no masks in the data set (they are in
    ground_truth/), no GNSS file."""
    out = tmp_path_factory.mktemp("synth-mask-free") / "tiny"
    return synthesize(preset("tiny"), out, masks=False, gnss=False, workers=2, show_progress=False)
