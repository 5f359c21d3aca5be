"""Fixtures of the VMA tests: a hand-drawn raster site and small BEV-only synthetic sites."""

from pathlib import Path

import numpy as np
import pytest

from models.vma.bev_sites import write_bev_site
from tests.vma.vma_test_sites import hand_drawn_site


@pytest.fixture()
def drawn_site(tmp_path: Path) -> Path:
    """A 60 m x 40 m site drawn by hand: a road with curbs, a dashed divider and a zebra crossing."""
    return hand_drawn_site(tmp_path / "drawn")


@pytest.fixture(scope="session")
def bev_sites(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Two BEV-only generator sites at 0.2 m/px: one to correct on, one to validate on (other seed, layout)."""
    root = tmp_path_factory.mktemp("vma_bev")
    return {
        "train": write_bev_site(3001, root / "train", resolution_m=0.2),
        "val": write_bev_site(3002, root / "val", resolution_m=0.2),
    }


@pytest.fixture()
def rng() -> np.random.Generator:
    return np.random.default_rng(0)
