"""Constants and builders shared by the annotation tests (imported by name: conftest.py is not importable)."""

from datetime import UTC, datetime
from typing import Any

import numpy as np

SITE_ORIGIN_XY = (100.0, 200.0)
RESOLUTION_M = 0.5
SIZE_PX = 40
PLANE = (0.1, -0.05, 2.0)
"""z = a * x_site + b * y_site + c."""


def plane_z(x: np.ndarray | float, y: np.ndarray | float) -> np.ndarray:
    """The known plane the test elevation raster is sampled from."""
    a, b, c = PLANE
    return np.asarray(a * np.asarray(x) + b * np.asarray(y) + c)


def element_kwargs(**changes: Any) -> dict[str, Any]:
    """Valid keyword arguments (JSON keys) for a human divider, with some replaced."""
    base: dict[str, Any] = {
        "id": "el-1",
        "class": "divider",
        "points_2d": [[0.0, 0.0], [5.0, 0.0], [10.0, 2.0]],
        "source": "human",
        "author": "alice",
        "created_at": datetime(2024, 5, 1, 12, 0, tzinfo=UTC),
        "updated_at": datetime(2024, 5, 1, 12, 5, tzinfo=UTC),
    }
    base.update(changes)
    return base


SQUARE = [[0.0, 0.0], [4.0, 0.0], [4.0, 4.0], [0.0, 4.0], [0.0, 0.0]]
