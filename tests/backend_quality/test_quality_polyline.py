"""`Polyline` agrees with shapely's linear referencing to the last bit, and finds self crossings without
noding the whole line (issue 21, point 3)."""

import numpy as np
import pytest
import shapely

from app.backend.quality.polyline import SHORT_LINE_SEGMENTS, Polyline


def _lines(rng: np.random.Generator) -> list[np.ndarray]:
    """Random walks, dense wiggly lines and grid-rounded lines (equal distances: ties between segments), all
    long enough for the index (shorter ones are left to shapely)."""
    lines = []
    for k in range(60):
        count = int(rng.integers(SHORT_LINE_SEGMENTS + 2, 300))
        if k % 3 == 0:
            lines.append(np.cumsum(rng.normal(0.0, 1.0, (count, 2)), axis=0))
        elif k % 3 == 1:
            lines.append(np.c_[np.linspace(0.0, 50.0, count), rng.uniform(-0.3, 0.3, count)])
        else:
            lines.append(np.round(rng.uniform(0.0, 10.0, (count, 2)), 1))
    return lines


def test_interpolate_and_locate_equal_shapely() -> None:
    rng = np.random.default_rng(1)
    for points in _lines(rng):
        line, polyline = shapely.LineString(points), Polyline(points)
        assert polyline.length_m == line.length
        distances = np.r_[rng.uniform(-5.0, line.length + 5.0, 100), 0.0, line.length, polyline.cumulative_m]
        expected = shapely.get_coordinates(shapely.line_interpolate_point(line, distances))
        np.testing.assert_array_equal(polyline.interpolate(distances), expected)
        low, high = points.min(axis=0) - 3.0, points.max(axis=0) + 3.0
        queries = np.r_[
            rng.uniform(low, high, (100, 2)), points, np.round(rng.uniform(0.0, 10.0, (30, 2)), 1)
        ]
        expected = shapely.line_locate_point(line, shapely.points(queries))
        np.testing.assert_array_equal(polyline.locate(queries, 1e9), expected)
        near = polyline.locate(queries, 2.0)
        far = shapely.distance(line, shapely.points(queries)) > 2.0
        np.testing.assert_array_equal(np.isnan(near), far)
        np.testing.assert_array_equal(near[~far], expected[~far])


def test_first_self_crossing_of_a_line_that_crosses_itself_thousands_of_times(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    x = np.linspace(0.0, 100.0, 5000)
    zigzag = np.c_[x + np.where(np.arange(5000) % 2, 0.5, -0.5), np.where(np.arange(5000) % 4 < 2, 0.0, 1.0)]
    line = shapely.LineString(zigzag)
    assert not line.is_simple
    monkeypatch.setattr(shapely, "node", _refuse)  # noding it gives ~5,000 parts, looped over in Python
    crossing = Polyline(zigzag).first_self_crossing()
    assert crossing == pytest.approx(_first_crossing_by_brute_force(zigzag[:40]))


def _first_crossing_by_brute_force(points: np.ndarray) -> tuple[float, float]:
    """Over every pair of non-neighbouring segments, the meeting point nearest the start along the line."""
    segments = [shapely.LineString(points[k : k + 2]) for k in range(len(points) - 1)]
    start_m = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))]
    best: tuple[float, tuple[float, float]] | None = None
    for a, first in enumerate(segments):
        for second in segments[a + 2 :]:
            meet = first.intersection(second)
            if meet.is_empty:
                continue
            for x, y in shapely.get_coordinates(meet):
                measure = start_m[a] + float(np.hypot(x - points[a, 0], y - points[a, 1]))
                if best is None or measure < best[0]:
                    best = (measure, (float(x), float(y)))
    assert best is not None
    return best[1]


def test_first_self_crossing_ignores_neighbours_and_a_closed_line_end() -> None:
    assert Polyline(np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 1.0]])).first_self_crossing() is None
    ring = np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 3.0], [0.0, 3.0], [0.0, 0.0]])
    assert Polyline(ring).first_self_crossing() is None
    back = np.array([[0.0, 0.0], [10.0, 0.0], [7.0, 0.0]])  # runs back over itself from x = 10 to 7
    assert Polyline(back).first_self_crossing() == (7.0, 0.0)
    loop = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 5.0], [5.0, 5.0], [5.0, -5.0]])
    assert Polyline(loop).first_self_crossing() == (5.0, 0.0)


def _refuse(*_args: object, **_kwargs: object) -> None:
    raise AssertionError("a per-vertex GEOS walk was called")
