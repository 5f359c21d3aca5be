"""Fixtures for the annotation tests: a small hand-made georeference and a planar elevation raster."""

import numpy as np
import pytest

from annotations import Georeference
from tests.annotations.annotation_helpers import RESOLUTION_M, SITE_ORIGIN_XY, SIZE_PX, plane_z


@pytest.fixture()
def georef() -> Georeference:
    """A 40 x 40 raster at 0.5 m whose pixel (0, 0) centre is at site (0, 20): site x in [0, 19.5], y in [0.5, 20]."""
    return Georeference(
        site_origin_xy=SITE_ORIGIN_XY,
        origin_xy=(SITE_ORIGIN_XY[0], SITE_ORIGIN_XY[1] + 20.0),
        resolution=RESOLUTION_M,
        width=SIZE_PX,
        height=SIZE_PX,
    )


@pytest.fixture()
def plane_elevation() -> np.ndarray:
    """Elevation raster sampled from the plane at the cell centres (row grows with -y)."""
    rows, cols = np.mgrid[0:SIZE_PX, 0:SIZE_PX]
    return plane_z(cols * RESOLUTION_M, 20.0 - rows * RESOLUTION_M).astype(np.float64)
