"""Sliding windows and the merging of per-window predictions into site vectors."""

import numpy as np
import pytest

from models.vma.infer import window_origins
from models.vma.merge import MergeConfig, clip_to_core, core_bounds, join_polylines, merge_windows
from models.vma.vectors import Vector


def test_windows_cover_the_site_with_overlap() -> None:
    origins = window_origins(300, 128, 32)
    assert origins[0] == 0 and origins[-1] == 300 - 128
    assert all(b - a <= 128 - 32 for a, b in zip(origins, origins[1:], strict=False))
    assert window_origins(100, 128, 32) == [0]
    with pytest.raises(ValueError, match="overlap_px"):
        window_origins(300, 128, 128)


def test_cores_tile_the_line() -> None:
    centres = [10.0, 30.0, 50.0]
    cores = [core_bounds(centres, i) for i in range(3)]
    assert cores[0][0] == -np.inf and cores[-1][1] == np.inf
    assert cores[0][1] == cores[1][0] == 20.0 and cores[1][1] == cores[2][0] == 40.0


def _line(x0: float, x1: float, score: float, y: float = 0.0) -> Vector:
    return Vector("divider", np.column_stack([np.linspace(x0, x1, 5), np.full(5, y)]), score)


def test_a_line_seen_by_two_windows_is_cut_at_the_border_and_joined() -> None:
    # window A sees x 0..30 (core x < 20), window B sees x 10..40 (core x >= 20); both see the whole line
    left = clip_to_core([_line(0.0, 30.0, 0.9)], (-np.inf, 20.0, -np.inf, np.inf), 1.0)
    right = clip_to_core([_line(10.0, 40.0, 0.5, y=0.2)], (20.0, np.inf, -np.inf, np.inf), 1.0)
    merged = merge_windows(left + right)
    assert len(merged) == 1
    xs = merged[0].points[:, 0]
    assert xs.min() == pytest.approx(0.0) and xs.max() == pytest.approx(40.0)
    assert merged[0].score == pytest.approx(0.7)  # length-weighted: 20 m at 0.9, 20 m at 0.5


def test_duplicates_are_suppressed_and_far_lines_kept() -> None:
    vectors = [_line(0, 20, 0.9), _line(0.5, 19.0, 0.4, y=0.3), _line(0, 20, 0.8, y=3.5)]
    merged = merge_windows(vectors, MergeConfig(join_gap_m=0.5))
    assert sorted(v.score for v in merged) == [0.8, 0.9]


def test_rings_are_kept_by_the_core_of_their_centroid() -> None:
    ring = Vector("ped_crossing", [[18, 0], [24, 0], [24, 4], [18, 4], [18, 0]], 0.8)
    assert clip_to_core([ring], (-np.inf, 20.0, -np.inf, np.inf), 1.0) == []
    assert clip_to_core([ring], (20.0, np.inf, -np.inf, np.inf), 1.0) == [ring]
    twin = Vector("ped_crossing", ring.points + 0.3, 0.5)
    assert len(merge_windows([ring, twin])) == 1


def test_join_respects_direction() -> None:
    across = [(np.array([[0.0, 0.0], [10.0, 0.0]]), 1.0), (np.array([[10.5, 0.5], [10.5, 10.0]]), 1.0)]
    assert len(join_polylines(across, 1.5, 45.0)) == 2
    along = [(np.array([[0.0, 0.0], [10.0, 0.0]]), 1.0), (np.array([[21.0, 0.0], [11.0, 0.0]]), 1.0)]
    joined = join_polylines(along, 1.5, 45.0)
    assert len(joined) == 1 and len(joined[0][0]) == 4
