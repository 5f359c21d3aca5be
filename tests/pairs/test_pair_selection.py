"""Sequential pairs within a clip and HSP pairs across clips, on hand-made drives."""

import math
from dataclasses import replace
from pathlib import Path

import pytest

from cama_pipeline.cameras import CameraView
from cama_pipeline.pairs.config import PairsConfig
from cama_pipeline.pairs.hsp import knn_candidates, spatial_pairs
from cama_pipeline.pairs.repeats import repeated_views
from cama_pipeline.pairs.sequential import overlapping_channels, sequential_pairs
from cama_pipeline.pairs.stage import free_height_offsets, select_pairs
from cama_pipeline.wigo.fusion import FREE_HEIGHT
from cama_pipeline.wigo.io import WigoFile, write_wigo
from cama_pipeline.workspace import Workspace
from tests.pairs.pair_views import view

RIG = {"CAM_FRONT": 0.0, "CAM_FRONT_LEFT": 55.0, "CAM_BACK": 180.0}


def drive(
    scene: str, start: tuple[float, float], heading_deg: float, frames: int, step_m: float = 4.0
) -> list[CameraView]:
    """A straight drive: every `step_m` a keyframe with the three rig cameras."""
    dx, dy = math.cos(math.radians(heading_deg)), math.sin(math.radians(heading_deg))
    return [
        view(
            start[0] + k * step_m * dx,
            start[1] + k * step_m * dy,
            heading_deg,
            channel=channel,
            mount_yaw_deg=mount,
            scene=scene,
            frame=k,
        )
        for k in range(frames)
        for channel, mount in RIG.items()
    ]


def names(views: list[CameraView], pairs: dict[tuple[int, int], str]) -> set[tuple[str, str, str]]:
    return {(views[i].token, views[j].token, reason) for (i, j), reason in pairs.items()}


def test_rig_overlap_comes_from_the_extrinsics() -> None:
    views = drive("a", (0, 0), 0, 1)
    assert overlapping_channels(views, 80.0) == {frozenset({"CAM_FRONT", "CAM_FRONT_LEFT"})}


def test_sequential_pairs_follow_the_windows_and_stay_in_their_clip() -> None:
    views = drive("a", (0, 0), 0, 6) + drive("b", (0, 0), 0, 6)
    pairs = names(views, sequential_pairs(views, PairsConfig(sequential_window=2, rig_window=1)))
    assert ("a-CAM_FRONT-0", "a-CAM_FRONT-2", "temporal") in pairs
    assert not any(a == "a-CAM_FRONT-0" and b == "a-CAM_FRONT-3" for a, b, _ in pairs)  # beyond the window
    assert ("a-CAM_FRONT-1", "a-CAM_FRONT_LEFT-1", "rig") in pairs
    assert ("a-CAM_FRONT-1", "a-CAM_FRONT_LEFT-2", "rig") in pairs
    assert not any(
        "CAM_BACK" in a and "CAM_FRONT" in b or "CAM_FRONT" in a and "CAM_BACK" in b
        for a, b, r in pairs
        if r == "rig"
    )
    assert not any(a[0] != b[0] for a, b, _ in pairs)  # never across clips


def test_hsp_finds_the_cross_clip_pairs_at_an_intersection() -> None:
    east = drive("east", (-40, 0), 0, 21)  # crosses the origin heading +x
    north = drive("north", (0, -40), 90, 21)  # crosses the origin heading +y
    far = drive("far", (500, 500), 0, 3)
    views = east + north + far
    config = PairsConfig()
    sequential = sequential_pairs(views, config)
    spatial, stats = spatial_pairs(views, config, exclude=set(sequential))
    cross = {(views[i].scene, views[j].scene) for i, j in spatial}
    assert ("east", "north") in cross or ("north", "east") in cross
    assert not any("far" in pair for pair in cross if len(set(pair)) == 2)
    fronts = [
        (views[i], views[j])
        for i, j in spatial
        if {views[i].scene, views[j].scene} == {"east", "north"}
        and views[i].channel == views[j].channel == "CAM_FRONT"
    ]
    for a, b in fronts:  # front cameras meet only where both look at the junction
        assert a.center[0] <= 1.5 and b.center[1] <= 1.5
    assert stats.candidates == stats.kept + sum(stats.dropped.values())
    assert stats.dropped["view_cone"] > 0 and stats.dropped["footprint"] > 0


def _lifted(views: list[CameraView], dz: float) -> list[CameraView]:
    """The views with their ego poses `dz` metres higher (a clip WIGO left at another height)."""
    out = []
    for v in views:
        pose = v.world_from_ego.copy()
        pose[2, 3] += dz
        out.append(replace(v, world_from_ego=pose))
    return out


def test_a_free_height_clip_is_paired_once_its_height_is_tied(tmp_path: Path) -> None:
    """The north drive 4 m too high (2D logged poses: WIGO's gauge, not the road): the height rule drops every
    pair across the two drives; tied to the east drive's road by `free_height_offsets` (its WIGO report says its
    height is free), the junction's cross pairs come back, as many as on level drives."""
    east, north = drive("east", (-40, 0), 0, 21), drive("north", (0, -40), 90, 21)
    workspace = Workspace(tmp_path / "workspace")
    for scene, report in (
        ("east", {"logged_pose_height": "fused"}),
        ("north", {"logged_pose_height": FREE_HEIGHT}),
    ):
        report = {**report, "global_constraint": "logged_pose"}
        write_wigo(workspace.wigo(scene), WigoFile(scene, scene, "x", {}, report, [], ()))
    level, lifted = east + north, east + _lifted(north, 4.0)

    def cross(views: list[CameraView], offsets: dict[str, float] | None) -> int:
        pairs, _ = select_pairs(views, PairsConfig(), offsets)
        return sum(1 for i, j in pairs if views[i].scene != views[j].scene)

    offsets = free_height_offsets(workspace, lifted, PairsConfig())
    assert offsets == {"north": pytest.approx(-4.0, abs=1e-9)}
    assert cross(lifted, None) == 0 < cross(level, None) == cross(lifted, offsets)
    assert free_height_offsets(workspace, lifted, PairsConfig(level_free_heights=False)) == {}
    assert select_pairs(lifted, PairsConfig(), offsets)[1]["free_height_offsets_m"] == offsets


def test_hsp_drops_other_road_levels_and_facing_cameras() -> None:
    below = view(0, 0, 0, scene="below")
    bridge = view(3, 0, 0, scene="bridge", z=6.0)
    facing = view(8, 0, 180, scene="oncoming")
    config = PairsConfig()
    spatial, stats = spatial_pairs([below, bridge, facing], config, exclude=set())
    assert spatial == {}
    assert stats.dropped["height"] == 2 and stats.dropped["face_to_face"] == 1


def test_knn_cap_and_radius() -> None:
    views = drive("a", (0, 0), 0, 30, step_m=2.0)
    everything = knn_candidates(views, PairsConfig(knn=0, knn_radius_m=10.0), exclude=set())
    capped = knn_candidates(views, PairsConfig(knn=3, knn_radius_m=10.0), exclude=set())
    assert set(capped) < set(everything)
    assert all(abs(views[i].center[0] - views[j].center[0]) <= 10.0 for i, j in everything)


def test_selection_is_a_small_share_of_exhaustive_on_a_long_drive() -> None:
    views = drive("a", (0, 0), 0, 40) + drive("b", (0, 4), 180, 40)
    pairs, funnel = select_pairs(views, PairsConfig())
    exhaustive = len(views) * (len(views) - 1) // 2
    assert len(pairs) < 0.2 * exhaustive and funnel["kept"] > 0


def test_a_stationary_clip_is_paired_through_its_first_view_only() -> None:
    north = drive("north", (0, -40), 90, 21)
    parked = drive("parked", (-6, 0), 0, 8, step_m=0.02)  # a car waiting at the junction: 8 frames, 14 cm
    views = north + parked
    config = PairsConfig()
    repeats = repeated_views(views, config)
    firsts = {i for i, v in enumerate(views) if v.scene == "parked" and v.frame_index == 0}
    assert set(repeats) == {i for i, v in enumerate(views) if v.scene == "parked" and v.frame_index > 0}
    assert set(repeats.values()) == firsts
    assert all(views[i].channel == views[r].channel for i, r in repeats.items())
    pairs, funnel = select_pairs(views, config)
    assert funnel["repeated_views"] == len(repeats)
    spatial = [pair for pair, reason in pairs.items() if reason == "hsp"]
    assert spatial and not any(i in repeats or j in repeats for i, j in spatial)
    assert any(i in firsts or j in firsts for i, j in spatial)  # the parked car's place is still paired
    for index, representative in repeats.items():
        assert pairs[(min(index, representative), max(index, representative))] in ("repeat", "temporal")
    unrepeated, _ = select_pairs(views, PairsConfig(repeat_distance_m=0))
    assert len(unrepeated) > len(pairs)
    assert not repeated_views(north, config)  # keyframes of a drive never repeat


def test_repeat_settings_are_checked() -> None:
    with pytest.raises(ValueError, match="repeat_distance_m"):
        PairsConfig(repeat_distance_m=-1.0)
