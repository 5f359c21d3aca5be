"""Fixtures shared by every test folder: a tiny synthetic site, generated once per session, read-only.

Missing dependencies (tests/dependency_policy.py, registered here as a plugin): a test that needs something not
installed (PostgreSQL's server programs, Chromium, a Python package) skips with a reason naming it, and fails
under CI (`CI=true`), since `make test` installs all of them. Under CI no test may skip at all: every skip of the
suite is one for a missing dependency (there is no skip for another reason, and no `skipif`), so the plugin
reports any skip under CI as a failure, a safety net for a skip that does not go through the policy's helpers. A
future skip for another reason would have to be allowed there explicitly.
"""

from dataclasses import dataclass
from pathlib import Path

import pytest

from cama_pipeline.features.config import FeaturesConfig
from cama_pipeline.synthetic.config import SynthConfig, preset
from cama_pipeline.synthetic.generate import SynthResult, run
from cama_studio.config import PipelineConfig
from cama_studio.pipeline import PipelineResult
from cama_studio.pipeline import run as run_pipeline

pytest_plugins = ["tests.dependency_policy"]


@dataclass(frozen=True)
class GeneratedSite:
    """A generated site and the config that made it."""

    config: SynthConfig
    result: SynthResult


@pytest.fixture(scope="session")
def tiny_site(tmp_path_factory: pytest.TempPathFactory) -> GeneratedSite:
    """The `tiny` preset generated with two render processes."""
    cfg = preset("tiny")
    out = tmp_path_factory.mktemp("synth") / "tiny"
    return GeneratedSite(cfg, run(cfg, out, workers=2, show_progress=False))


@pytest.fixture()
def site_root(tiny_site: GeneratedSite) -> Path:
    """Root folder of the tiny site."""
    return tiny_site.result.out_dir


@pytest.fixture(scope="session")
def whole_path(tiny_site: GeneratedSite, tmp_path_factory: pytest.TempPathFactory) -> PipelineResult:
    """`cama run` on the tiny site once (rule-based proposals, 1024 SIFT features): every stage's outputs."""
    workspace = tmp_path_factory.mktemp("whole-path") / "workspace"
    config = PipelineConfig(proposer="rule", features=FeaturesConfig(max_num_features=1024))
    return run_pipeline(tiny_site.result.out_dir / "nuscenes", workspace, config)
