"""Site aggregation on hand-made tracks: overlap groups, night drops, stationary merges, reasons."""

import numpy as np
import pytest

from cama_pipeline.site.aggregate import SceneTrack, aggregate, track_distance_m
from cama_pipeline.site.config import SiteConfig


def line(x0: float, x1: float, y: float, n: int = 20) -> np.ndarray:
    return np.column_stack([np.linspace(x0, x1, n), np.full(n, y), np.zeros(n)])


def test_overlapping_scenes_share_a_site_transitively() -> None:
    tracks = [
        SceneTrack("a", line(0, 60, 0), False),
        SceneTrack("b", line(80, 140, 5), False),  # 20 m from a's end
        SceneTrack("c", line(160, 220, 0), False),  # 20 m from b's end, 100 m from a
        SceneTrack("far", line(1000, 1060, 0), False),
    ]
    result = aggregate(tracks, SiteConfig(overlap_radius_m=30.0))
    assert [s.scenes for s in result.sites] == [("a", "b", "c"), ("far",)]
    assert [s.site_id for s in result.sites] == ["site-001", "site-002"]
    assert result.dropped == {}


def test_night_scene_dropped_with_its_reason_and_stationary_merged_into_nearest() -> None:
    tracks = [
        SceneTrack("east", line(0, 60, 0), False),
        SceneTrack("west", line(0, 60, 40), False),
        SceneTrack("night", line(0, 60, 2), False, night_reason="night: description says so"),
        SceneTrack("wait", line(30, 30.2, 37), True),
    ]
    result = aggregate(tracks, SiteConfig(overlap_radius_m=30.0))
    assert result.dropped == {"night": "night: description says so"}
    (site,) = [s for s in result.sites if "wait" in s.scenes]
    assert site.merged == {"wait": "west"}
    assert "east" not in site.scenes  # 40 m apart: separate sites


def test_stationary_clip_without_moving_clip_near_is_dropped() -> None:
    tracks = [SceneTrack("move", line(0, 60, 0), False), SceneTrack("wait", line(500, 500, 0, 3), True)]
    result = aggregate(tracks, SiteConfig(stationary_merge_max_m=100.0))
    assert "nearest moving clip (move) is 440 m away" in result.dropped["wait"]
    only_still = aggregate([SceneTrack("wait", line(0, 0, 0, 3), True)], SiteConfig())
    assert "no moving day clip" in only_still.dropped["wait"] and only_still.sites == ()


def test_track_distance_is_horizontal_and_inf_when_empty() -> None:
    a = np.array([[0.0, 0.0, 0.0]])
    assert track_distance_m(a, np.array([[3.0, 4.0, 100.0]])) == pytest.approx(5.0)
    assert track_distance_m(a, np.zeros((0, 3))) == float("inf")


def test_config_validation_names_the_field() -> None:
    with pytest.raises(ValueError, match="overlap_radius_m"):
        SiteConfig(overlap_radius_m=-1.0)
    with pytest.raises(ValueError, match="brightness_images"):
        SiteConfig(brightness_images=0)


def test_scenes_of_different_locations_never_share_a_site() -> None:
    tracks = [
        SceneTrack("boston-a", line(0, 60, 0), False, location="boston"),
        SceneTrack("singapore-a", line(0, 60, 1), False, location="singapore"),  # same coordinates
        SceneTrack("boston-b", line(50, 110, 2), False, location="boston"),
        SceneTrack("singapore-wait", line(30, 30.2, 1, 3), True, location="singapore"),
        SceneTrack("paris-wait", line(30, 30.2, 1, 3), True, location="paris"),
    ]
    result = aggregate(tracks, SiteConfig(overlap_radius_m=30.0))
    assert [(s.site_id, s.location, s.scenes) for s in result.sites] == [
        ("site-001", "boston", ("boston-a", "boston-b")),
        ("site-002", "singapore", ("singapore-a", "singapore-wait")),
    ]
    assert result.sites[1].merged == {"singapore-wait": "singapore-a"}
    assert result.dropped == {
        "paris-wait": "stationary and no moving day clip at its location (paris) to merge with"
    }
