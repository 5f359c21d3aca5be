"""Proposal-to-final diffs with known answers."""

import pytest

from app.backend.quality import proposal_diff

PROPOSAL = [(0.0, 0.0), (5.0, 0.0), (10.0, 0.0)]


def test_identical_is_unchanged() -> None:
    diff = proposal_diff(PROPOSAL, list(PROPOSAL), proposal_cls="divider", final_cls="divider")
    assert diff.unchanged and not diff.class_changed
    assert (diff.chamfer_m, diff.vertices_moved, diff.vertices_added, diff.vertices_removed) == (0.0, 0, 0, 0)


def test_one_vertex_moved() -> None:
    diff = proposal_diff(PROPOSAL, [(0.0, 0.0), (5.0, 0.5), (10.0, 0.0)])
    assert not diff.unchanged
    assert (diff.vertices_moved, diff.vertices_added, diff.vertices_removed) == (1, 0, 0)
    assert 0.0 < diff.chamfer_m < 0.5
    assert diff.mean_displacement_m == pytest.approx(0.5 / 3)


def test_vertices_added_and_removed() -> None:
    added = proposal_diff(PROPOSAL, [(0.0, 0.0), (2.5, 0.0), (5.0, 0.0), (10.0, 0.0)])
    assert (added.vertices_moved, added.vertices_added, added.vertices_removed) == (0, 1, 0)
    assert added.chamfer_m == pytest.approx(0.0, abs=1e-9) and not added.unchanged
    removed = proposal_diff(PROPOSAL, [(0.0, 0.0), (10.0, 0.0)])
    assert (removed.vertices_added, removed.vertices_removed) == (0, 1)
    far = proposal_diff(PROPOSAL, [(0.0, 0.0), (5.0, 4.0), (10.0, 0.0)])
    assert (far.vertices_moved, far.vertices_added, far.vertices_removed) == (0, 1, 1)


def test_class_change_is_not_unchanged() -> None:
    diff = proposal_diff(PROPOSAL, PROPOSAL, proposal_cls="divider", final_cls="boundary")
    assert diff.class_changed and not diff.unchanged


def test_closed_ring_counts_its_corners_once() -> None:
    ring = [(0.0, 0.0), (4.0, 0.0), (4.0, 6.0), (0.0, 6.0), (0.0, 0.0)]
    moved = [(0.0, 0.0), (4.0, 0.0), (4.0, 6.5), (0.0, 6.0), (0.0, 0.0)]
    diff = proposal_diff(ring, moved, proposal_cls="ped_crossing", final_cls="ped_crossing")
    assert (diff.vertices_moved, diff.vertices_added, diff.vertices_removed) == (1, 0, 0)
    assert diff.mean_displacement_m == pytest.approx(0.5 / 4)


def test_bad_points_raise() -> None:
    with pytest.raises(ValueError, match="final_points"):
        proposal_diff(PROPOSAL, [(0.0, 0.0)])
