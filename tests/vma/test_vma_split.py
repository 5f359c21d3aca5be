"""The location-disjoint split: overlapping scenes stay together; impossible splits are refused."""

import numpy as np
import pytest

from models.vma.split import SplitConfig, location_groups, split_scenes


def _track(x0: float, y0: float) -> np.ndarray:
    return np.column_stack([np.linspace(x0, x0 + 100, 20), np.full(20, y0)])


TRAJECTORIES = {
    "a1": _track(0, 0),
    "a2": _track(50, 20),  # overlaps a1
    "a3": _track(140, 40),  # overlaps a2 only: same location transitively
    "b1": _track(0, 1000),
    "c1": _track(5000, 0),
    "c2": _track(5000, 10),
    "d1": _track(-3000, -3000),
}


def test_overlapping_scenes_form_one_location() -> None:
    groups = location_groups(TRAJECTORIES, 50.0)
    assert ["a1", "a2", "a3"] in groups and ["c1", "c2"] in groups and len(groups) == 4


@pytest.mark.parametrize("seed", range(6))
def test_no_location_on_both_sides(seed: int) -> None:
    split = split_scenes(TRAJECTORIES, SplitConfig(val_share=0.3, seed=seed))
    assert split.train and split.val
    assert set(split.train) | set(split.val) == set(TRAJECTORIES)
    assert not set(split.train) & set(split.val)
    for group in split.groups:
        assert set(group) <= set(split.train) or set(group) <= set(split.val)


def test_split_is_deterministic() -> None:
    assert split_scenes(TRAJECTORIES, SplitConfig(seed=3)) == split_scenes(TRAJECTORIES, SplitConfig(seed=3))


def test_one_location_cannot_be_split() -> None:
    with pytest.raises(ValueError, match="share one location"):
        split_scenes({"a1": _track(0, 0), "a2": _track(10, 10)})
    with pytest.raises(ValueError, match="at least 2 scenes"):
        split_scenes({"a1": _track(0, 0)})
    with pytest.raises(ValueError, match="scene 'bad'"):
        split_scenes({"a1": _track(0, 0), "bad": np.array([[np.nan, 0.0]])})
    with pytest.raises(ValueError, match="val_share"):
        SplitConfig(val_share=1.0)
