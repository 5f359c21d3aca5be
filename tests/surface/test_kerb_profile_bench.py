"""`bench/kerb_profile.py` bins the surface stage's decisions by signed distance from the true road edge, and
reads each cell at its true height: road level on the road, curb height beyond it."""

import numpy as np
import pytest

from bench.kerb_profile import profile, signed_edge_distance
from cama_pipeline.bev import BevRasters, RasterGeoreference
from cama_pipeline.semantics import BEV_CLASSES, Semantic


def _shares(cls: Semantic, n: int) -> np.ndarray:
    out = np.zeros((n, len(BEV_CLASSES)))
    out[:, BEV_CLASSES.index(cls)] = 1.0
    return out


def test_the_edge_distance_is_negative_on_the_road_and_positive_beyond() -> None:
    geo = RasterGeoreference(origin_xy=(0.0, 0.0), resolution=0.1, width=3, height=6)
    semantic = np.array(
        [int(Semantic.LANE_MARKING)] + [int(Semantic.ROAD)] * 2 + [int(Semantic.CURB)] * 2 + [0]
    )
    truth = BevRasters(geo, semantic=np.repeat(semantic[:, None], 3, axis=1).astype(np.uint8))
    distance = signed_edge_distance(truth)[:, 1]
    assert distance == pytest.approx([-0.3, -0.2, -0.1, 0.1, 0.2, 0.3])


def test_bins_report_the_true_curb_and_what_each_height_reads() -> None:
    # two road cells and two curb cells; the road-level vote calls everything road, the curb-height vote curb
    distance = np.array([-0.15, -0.05, 0.12, 0.18])
    true_class = np.array([int(Semantic.ROAD)] * 2 + [int(Semantic.CURB)] * 2)
    road_level, curb_height = _shares(Semantic.ROAD, 4), _shares(Semantic.CURB, 4)
    label = np.array([int(Semantic.ROAD)] * 3 + [int(Semantic.CURB)])
    rows = profile(
        distance,
        true_class,
        road_level,
        curb_height,
        score=np.array([-1.0, 0.5, 1.0, 2.0]),
        raised=np.array([False, False, False, True]),
        label=label,
        edges=np.array([-0.2, -0.1, 0.0, 0.1, 0.2]),
    )
    assert [(r["from_m"], r["cells"]) for r in rows] == [
        (-0.2, 1),
        (-0.1, 1),
        (0.1, 2),
    ]  # the empty bin left out
    curb = rows[-1]
    assert curb["true_curb_share"] == 1.0 and curb["raised_share"] == 0.5 and curb["median_score"] == 1.5
    assert curb["road_level_shares"] == {"road": 1.0, "curb": 0.0, "background": 0.0}
    assert curb["curb_height_shares"]["curb"] == 1.0
    assert curb["labelled"] == {"road": 0.5, "curb": 0.5, "background": 0.0} and curb["right"] == 0.5
    # at its true height every cell reads right: road at road level, curb at curb height
    assert all(r["right_at_true_height"] == 1.0 for r in rows)
