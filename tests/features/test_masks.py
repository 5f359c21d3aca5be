"""Feature masks: vehicle and ego-body pixels, dilated, block keypoints."""

import numpy as np

from cama_pipeline.features.masks import blocked_pixels, keypoints_allowed
from cama_pipeline.semantics import Semantic


def test_blocked_pixels_cover_the_classes_and_grow_by_the_dilation() -> None:
    semantic = np.full((40, 60), int(Semantic.ROAD), dtype=np.uint8)
    semantic[10:20, 10:20] = int(Semantic.VEHICLE)
    semantic[35:, :] = int(Semantic.EGO)
    raw = blocked_pixels(semantic, (int(Semantic.VEHICLE), int(Semantic.EGO)), 0)
    assert raw.sum() == 100 + 5 * 60
    grown = blocked_pixels(semantic, (int(Semantic.VEHICLE), int(Semantic.EGO)), 3)
    assert grown[7, 15] and grown[15, 22] and not grown[5, 15] and grown[32, 0]
    assert not blocked_pixels(semantic, (int(Semantic.CROSSWALK),), 3).any()


def test_keypoints_on_blocked_pixels_are_dropped() -> None:
    blocked = np.zeros((40, 60), dtype=bool)
    blocked[10:20, 10:20] = True
    keypoints = np.array([[15.2, 14.8], [5.0, 5.0], [59.9, 39.9], [9.4, 10.0]])
    assert keypoints_allowed(keypoints, blocked).tolist() == [False, True, True, True]
    assert keypoints_allowed(np.zeros((0, 2)), blocked).shape == (0,)
