"""Shared fixtures of the evaluation tests: a hand-written nuScenes-layout data set from tests/data."""

from pathlib import Path

import pytest

from tests.data.nuscenes_fixture import NuScenesFixture, write_nuscenes_fixture


@pytest.fixture()
def small_dataset(tmp_path: Path) -> NuScenesFixture:
    """A one-scene, 2-sample data set with masks, 64x36 px images."""
    return write_nuscenes_fixture(tmp_path / "nuscenes", n_samples=2, width=64, height=36)
