"""Lane instances from a semantic mask: a perspective drawing of a road (two dashed lines, a double line, a
crosswalk, a curb) gives one instance per line, crossing and curb, as the generator's instance masks do."""

import cv2
import numpy as np
import pytest

from cama_pipeline.segment.instances import lane_instances
from cama_pipeline.semantics import INSTANCE_ID_BASE, Semantic

WIDTH, HEIGHT, FOCAL, CAMERA_HEIGHT_M = 512, 288, 400.0, 1.5


def _quad(mask: np.ndarray, x0: float, x1: float, z0: float, z1: float, cls: Semantic) -> None:
    """Fill the ground rectangle [x0, x1] x [z0, z1] (metres: lateral, depth) as seen by a level camera."""
    corners = [(x, z) for x, z in ((x0, z0), (x1, z0), (x1, z1), (x0, z1))]
    pixels = [(WIDTH / 2 + FOCAL * x / z, 100 + FOCAL * CAMERA_HEIGHT_M / z) for x, z in corners]
    cv2.fillPoly(mask, [np.round(np.array(pixels) * 8).astype(np.int32)], int(cls), shift=3)


def road() -> np.ndarray:
    """Road with dashed lines (4 m dashes every 9 m) at x = -1.75 and 1.75 m, a double line at 5.25 m, a crosswalk of eight stripes
    at 5-8 m depth, and a curb at -7 m."""
    mask = np.full((HEIGHT, WIDTH), int(Semantic.SKY), np.uint8)
    mask[100:] = int(Semantic.ROAD)
    for x in (-1.75, 1.75):
        for z in np.arange(9.0, 60.0, 9.0):
            _quad(mask, x - 0.1, x + 0.1, z, z + 4.0, Semantic.LANE_MARKING)
    for x in (5.1, 5.4):
        _quad(mask, x - 0.075, x + 0.075, 9.0, 60.0, Semantic.LANE_MARKING)
    for x in np.arange(-3.75, 4.0, 1.0):
        _quad(mask, x, x + 0.5, 5.0, 8.0, Semantic.CROSSWALK)
    _quad(mask, -7.1, -6.9, 4.0, 60.0, Semantic.CURB)
    return mask


def instances_of(instances: np.ndarray, cls: Semantic) -> list[int]:
    values = np.unique(instances)
    return [int(v) for v in values if v // INSTANCE_ID_BASE == int(cls)]


def test_one_instance_per_line_crossing_and_curb() -> None:
    semantic = road()
    instances = lane_instances(semantic)
    assert instances.dtype == np.uint16 and instances.shape == semantic.shape
    lanes = instances_of(instances, Semantic.LANE_MARKING)
    assert lanes == [3001, 3002, 3003]  # two dashed lines and the double line, each one instance
    assert instances_of(instances, Semantic.CROSSWALK) == [4001]
    assert instances_of(instances, Semantic.CURB) == [2001]
    marked = semantic == int(Semantic.LANE_MARKING)
    given = instances // INSTANCE_ID_BASE == int(Semantic.LANE_MARKING)
    assert not (given & ~marked).any() and given.sum() >= 0.98 * marked.sum()  # only specks go without


def test_dashes_of_one_line_share_its_instance_and_lines_stay_apart() -> None:
    semantic = road()
    instances = lane_instances(semantic)
    for x in (-1.75, 1.75):  # the centres of the three nearest dashes of each dashed line
        centres = [
            (round(WIDTH / 2 + FOCAL * x / (z + 2.0)), round(100 + FOCAL * CAMERA_HEIGHT_M / (z + 2.0)))
            for z in (9.0, 18.0, 27.0)
        ]
        values = {int(instances[v, u]) for u, v in centres}
        assert len(values) == 1 and values != {0}
    left = instances[round(100 + FOCAL * CAMERA_HEIGHT_M / 11), round(WIDTH / 2 - FOCAL * 1.75 / 11)]
    right = instances[round(100 + FOCAL * CAMERA_HEIGHT_M / 11), round(WIDTH / 2 + FOCAL * 1.75 / 11)]
    assert left != right


def test_specks_are_not_instances_and_sizes_scale() -> None:
    semantic = np.full((HEIGHT, WIDTH), int(Semantic.ROAD), np.uint8)
    semantic[10:12, 10:12] = int(Semantic.LANE_MARKING)  # 4 px: noise
    assert not lane_instances(semantic).any()
    small = cv2.resize(road(), (WIDTH // 2, HEIGHT // 2), interpolation=cv2.INTER_NEAREST)
    instances = lane_instances(small)
    sizes = [int((instances == v).sum()) for v in instances_of(instances, Semantic.LANE_MARKING)]
    assert len([s for s in sizes if s >= 12]) == 3  # the double line and the nearest dash of each line


def test_a_mask_that_is_not_2d_is_refused() -> None:
    with pytest.raises(ValueError, match="2D"):
        lane_instances(np.zeros((4, 4, 3), np.uint8))
