"""Geometry: validation, resampling, densifying, simplification and clipping to the MapTR range."""

import numpy as np
import pytest
from shapely.geometry import Polygon

from annotations import (
    MAPTR_RANGE,
    clip_to_box,
    densify,
    resample_fixed,
    resample_spacing,
    simplify,
    validate_geometry,
)
from tests.annotations.annotation_helpers import SQUARE


def test_validate_geometry_returns_array_and_rejects_bad_shapes() -> None:
    assert validate_geometry([[0, 0], [1, 0]], closed=False).shape == (2, 2)
    with pytest.raises(ValueError, match="vertices: expected a list of"):
        validate_geometry([0.0, 1.0], closed=False, field="vertices")
    with pytest.raises(ValueError, match="points_3d: expected 3 coordinates"):
        validate_geometry([[0, 0], [1, 0]], closed=False, field="points_3d", dims=3)
    with pytest.raises(ValueError, match="at least 4 points"):
        validate_geometry([[0, 0], [1, 0], [0, 0]], closed=True)


def test_resample_fixed_on_a_straight_line_gives_exact_points() -> None:
    out = resample_fixed([[0.0, 0.0], [10.0, 0.0]], 6)
    np.testing.assert_array_equal(out, [[0, 0], [2, 0], [4, 0], [6, 0], [8, 0], [10, 0]])


def test_resample_fixed_follows_corners_and_keeps_ends() -> None:
    out = resample_fixed([[0.0, 0.0], [4.0, 0.0], [4.0, 4.0]], 5)
    np.testing.assert_allclose(out, [[0, 0], [2, 0], [4, 0], [4, 2], [4, 4]], atol=1e-12)
    uneven = resample_fixed([[0.0, 0.0], [0.3, 0.0], [7.0, 1.0], [7.5, 9.0]], 20)
    np.testing.assert_array_equal(uneven[[0, -1]], [[0.0, 0.0], [7.5, 9.0]])
    steps = np.linalg.norm(np.diff(resample_fixed([[0, 0], [3, 0], [3, 3]], 7), axis=0), axis=1)
    np.testing.assert_allclose(steps, 1.0)


def test_resample_fixed_polygon_along_the_closed_ring() -> None:
    out = resample_fixed(SQUARE, 9)
    expected = [[0, 0], [2, 0], [4, 0], [4, 2], [4, 4], [2, 4], [0, 4], [0, 2], [0, 0]]
    np.testing.assert_allclose(out, expected, atol=1e-12)


def test_resample_interpolates_z_along_the_plane_length() -> None:
    out = resample_fixed([[0.0, 0.0, 1.0], [4.0, 0.0, 3.0]], 3)
    np.testing.assert_allclose(out, [[0, 0, 1], [2, 0, 2], [4, 0, 3]])


def _chamfer_ap_resample(points: np.ndarray, num_points: int) -> np.ndarray:
    """The twin `cama_pipeline.evaluate.chamfer_ap.resample` had, before resample_fixed replaced it."""
    points = np.asarray(points, dtype=np.float64)
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])
    if arc[-1] <= 0:
        return np.repeat(points[:1], num_points, axis=0)
    targets = np.linspace(0.0, arc[-1], num_points)
    return np.column_stack([np.interp(targets, arc, points[:, d]) for d in range(points.shape[1])])


def _previous_resample_fixed(points: np.ndarray, n: int) -> np.ndarray:
    """resample_fixed before the merge: stations up to the pairwise-summed length instead of the last arc."""
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points[:, :2], axis=0), axis=1))])
    keep = np.concatenate([[True], np.diff(arc) > 0])
    stations = np.linspace(0.0, float(np.linalg.norm(np.diff(points[:, :2], axis=0), axis=1).sum()), n)
    out = np.stack([np.interp(stations, arc[keep], points[keep, k]) for k in range(points.shape[1])], axis=1)
    out[0], out[-1] = points[0], points[-1]
    return out


def test_resample_fixed_equals_both_twins_it_replaced() -> None:
    """Bit for bit the Chamfer-AP / VMA resampling (so proposals do not change), within 1e-12 m the previous
    resample_fixed (MapTR export), on random polylines with repeated vertices and zero-length ones."""
    rng = np.random.default_rng(22)
    for trial in range(2000):
        points = np.cumsum(rng.normal(0.0, 3.0, (int(rng.integers(2, 60)), 2)), axis=0) + rng.uniform(
            -500, 500, 2
        )
        if trial % 5 == 0:
            points = np.repeat(points, rng.integers(1, 3, len(points)), axis=0)
        n = int(rng.integers(2, 120))
        if trial % 50 == 0:
            points = np.repeat(points[:1], len(points), axis=0)
            np.testing.assert_array_equal(resample_fixed(points, n), _chamfer_ap_resample(points, n))
            continue
        np.testing.assert_array_equal(resample_fixed(points, n), _chamfer_ap_resample(points, n))
        np.testing.assert_allclose(
            resample_fixed(points, n), _previous_resample_fixed(points, n), rtol=0, atol=1e-12
        )


def test_resample_spacing() -> None:
    out = resample_spacing([[0.0, 0.0], [10.0, 0.0]], 3.0)  # 4 steps of 2.5 m
    np.testing.assert_allclose(out[:, 0], [0, 2.5, 5, 7.5, 10])
    exact = resample_spacing([[0.0, 0.0], [10.0, 0.0]], 2.0)
    np.testing.assert_allclose(exact[:, 0], [0, 2, 4, 6, 8, 10])
    assert len(resample_spacing([[0.0, 0.0], [1.0, 0.0]], 5.0)) == 2


@pytest.mark.parametrize(
    ("call", "field"),
    [(lambda: resample_fixed(SQUARE, 1), "n"), (lambda: resample_spacing(SQUARE, 0), "spacing_m")],
)
def test_resample_rejects_bad_parameters(call: object, field: str) -> None:
    with pytest.raises(ValueError, match=field):
        call()  # type: ignore[operator]


def test_densify_keeps_original_vertices() -> None:
    original = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 2.2]])
    out = densify(original, 0.5)
    assert max(np.linalg.norm(np.diff(out, axis=0), axis=1)) <= 0.5 + 1e-12
    for vertex in original:
        assert np.any(np.all(np.isclose(out, vertex), axis=1))
    assert len(out) == 1 + 2 + 5


def test_simplify_keeps_ends_and_drops_small_wiggles() -> None:
    line = np.array([[0, 0, 1.0], [1, 0.01, 1.1], [2, -0.01, 1.2], [3, 0, 1.3], [3, 3, 1.4]])
    out = simplify(line, 0.05)
    np.testing.assert_array_equal(out, line[[0, 3, 4]])  # corner kept with its own z
    np.testing.assert_array_equal(simplify(line, 0.001), line)
    np.testing.assert_array_equal(simplify(line[[0, 4]], 10.0), line[[0, 4]])
    with pytest.raises(ValueError, match="tolerance_m"):
        simplify(line, -1.0)


def test_clip_cuts_a_line_at_the_range_boundary() -> None:
    pieces = clip_to_box([[-40.0, 0.0, 0.0], [40.0, 0.0, 8.0]], *MAPTR_RANGE)
    assert len(pieces) == 1
    np.testing.assert_allclose(pieces[0], [[-30, 0, 1], [30, 0, 7]])  # z interpolated at the cuts
    half = clip_to_box([[0.0, 0.0], [0.0, 20.0]], *MAPTR_RANGE)
    np.testing.assert_allclose(half[0], [[0, 0], [0, 15]])


def test_clip_splits_a_line_that_leaves_and_comes_back() -> None:
    line = [[0.0, 0.0], [40.0, 0.0], [40.0, 5.0], [0.0, 5.0]]
    pieces = clip_to_box(line, *MAPTR_RANGE)
    assert len(pieces) == 2
    np.testing.assert_allclose(pieces[0], [[0, 0], [30, 0]])
    np.testing.assert_allclose(pieces[1], [[30, 5], [0, 5]])  # direction kept


def test_clip_outside_gives_nothing() -> None:
    assert clip_to_box([[40.0, 0.0], [50.0, 0.0]], *MAPTR_RANGE) == []
    assert clip_to_box([[30.0, -20.0], [30.0, 20.0]], 0.0, 29.0, -15.0, 15.0) == []
    with pytest.raises(ValueError, match="xmin < xmax"):
        clip_to_box([[0.0, 0.0], [1.0, 0.0]], 1.0, 0.0, -1.0, 1.0)


def test_clip_polygon_stays_a_closed_polygon() -> None:
    square = [[-40.0, -5.0], [0.0, -5.0], [0.0, 5.0], [-40.0, 5.0], [-40.0, -5.0]]
    pieces = clip_to_box(square, *MAPTR_RANGE, closed=True)
    assert len(pieces) == 1
    ring = pieces[0]
    np.testing.assert_array_equal(ring[0], ring[-1])
    assert Polygon(ring).area == pytest.approx(300.0)
    assert ring[:, 0].min() == pytest.approx(-30.0)
    u_shape = [[-40, -10], [40, -10], [40, 10], [-40, 10], [-40, 5], [35, 5], [35, -5], [-40, -5], [-40, -10]]
    assert len(clip_to_box(u_shape, -30.0, 30.0, -15.0, 15.0, closed=True)) == 2
