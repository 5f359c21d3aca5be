"""True vectors cut to the observed cells of a raster: stretches kept, short leftovers and unseen rings dropped."""

import numpy as np

from cama_pipeline.evaluate.observed import ObservedMask, observed_parts
from cama_pipeline.semantics import Semantic

ORIGIN, RES = (100.0, 50.0), 0.1  # 40 m x 20 m raster: x 100..140, y 50..30


def _mask(seen_x: tuple[float, float]) -> ObservedMask:
    semantic = np.full((200, 400), int(Semantic.UNOBSERVED), np.uint8)
    c0, c1 = round((seen_x[0] - ORIGIN[0]) / RES), round((seen_x[1] - ORIGIN[0]) / RES)
    semantic[:, c0:c1] = int(Semantic.ROAD)
    semantic[100, c0 + 50] = int(Semantic.UNOBSERVED)  # a one-cell hole of label noise
    return ObservedMask.from_semantic(semantic, ORIGIN, RES)


def test_a_line_keeps_only_its_observed_stretch() -> None:
    line = np.array([[95.0, 40.0], [145.0, 40.0]])  # starts and ends outside the raster
    parts = observed_parts(line, False, _mask((110.0, 125.0)))
    assert len(parts) == 1
    assert abs(parts[0][0, 0] - 110.0) <= 0.3 and abs(parts[0][-1, 0] - 125.0) <= 0.3
    np.testing.assert_allclose(parts[0][:, 1], 40.0)


def test_short_leftovers_and_mostly_unseen_rings_are_dropped() -> None:
    mask = _mask((110.0, 111.5))
    assert observed_parts(np.array([[100.0, 40.0], [140.0, 40.0]]), False, mask) == []
    ring = np.array([[109.0, 45.0], [113.0, 45.0], [113.0, 35.0], [109.0, 35.0], [109.0, 45.0]])
    assert observed_parts(ring, True, mask) == []
    seen_ring = observed_parts(ring, True, _mask((105.0, 130.0)))
    assert len(seen_ring) == 1 and np.array_equal(seen_ring[0], ring)
