"""Fixtures of the SfM tests: the tiny site's SfM inputs, built once per session."""

from pathlib import Path

import pytest

from tests.sfm.sfm_fixture import SfmInputs, build_sfm_inputs


@pytest.fixture(scope="session")
def sfm_inputs(tiny_site: object, tmp_path_factory: pytest.TempPathFactory) -> SfmInputs:
    """The tiny site after wigo, keyframes, sites, pairs and features (read-only: copy before changing)."""
    return build_sfm_inputs(Path(tiny_site.result.out_dir), tmp_path_factory.mktemp("sfm"))  # type: ignore[attr-defined]
