"""The rule-based proposer on a hand-drawn raster: one joined divider, two curbs, one crossing, sane confidence."""

from pathlib import Path

import numpy as np
import pytest
from shapely.geometry import LineString, Polygon

from cama_pipeline.semantics import Semantic
from models.vma.evaluate import evaluate_proposer
from models.vma.rasters import load_site_rasters
from models.vma.rule_based import RuleConfig, drop_kinks, propose_rule_based, trim_hooks
from tests.vma.vma_test_sites import drawn_semantic, global_xy, pixel, write_raster_site


def test_drawn_site_gives_the_drawn_vectors(drawn_site: Path) -> None:
    vectors = propose_rule_based(load_site_rasters(drawn_site))
    by_class = {c: [v for v in vectors if v.cls == c] for c in ("divider", "boundary", "ped_crossing")}
    assert len(by_class["boundary"]) == 2
    assert len(by_class["ped_crossing"]) == 1
    assert len(by_class["divider"]) == 2, "dashes (6 m gaps) joined, not across the 15 m crossing"
    dividers = sorted((LineString(v.points) for v in by_class["divider"]), key=lambda line: line.bounds[0])
    for divider, (x0, x1) in zip(dividers, ((1, 22), (37, 58)), strict=True):
        truth = LineString([global_xy(x0, 20), global_xy(x1, 20)])
        assert divider.hausdorff_distance(truth) < 0.5
    ring = Polygon(by_class["ped_crossing"][0].points)
    drawn = Polygon([global_xy(30, 12.5), global_xy(34, 12.5), global_xy(34, 27.5), global_xy(30, 27.5)])
    assert ring.intersection(drawn).area / ring.union(drawn).area > 0.8
    for boundary in by_class["boundary"]:
        assert boundary.score > max(v.score for v in by_class["divider"]), (
            "solid curbs are better supported than dashes"
        )
    assert all(0.0 <= v.score <= 1.0 for v in vectors)


def test_no_join_leaves_dashes_apart(drawn_site: Path) -> None:
    vectors = propose_rule_based(load_site_rasters(drawn_site), RuleConfig(join_gap_m=1.0, min_length_m=1.0))
    assert len([v for v in vectors if v.cls == "divider"]) >= 5


def test_rule_based_is_near_perfect_on_its_drawing(drawn_site: Path) -> None:
    report = evaluate_proposer(propose_rule_based, [drawn_site])
    assert report["mean_ap"] > 0.8
    assert report["num_ground_truth"] == 5
    assert report["seconds_per_km2"] > 0
    assert (
        sum(b["count"] for b in report["confidence_bins"]) >= report["num_predictions"]
    )  # tile-clipped pieces


def test_road_edge_boundaries_follow_the_road_past_a_smeared_curb_and_stop_where_nothing_was_seen(
    tmp_path: Path,
) -> None:
    semantic, vectors = drawn_semantic()
    top = pixel(0, 12)[1]
    semantic[pixel(0, 10.5)[1] : top + 1] = int(Semantic.CURB)  # a curb label smeared 1.5 m over the sidewalk
    semantic[top - 2 : top + 1] = int(Semantic.UNOBSERVED)  # and its face hid a thin strip
    semantic[: top + 1, pixel(40, 0)[0] :] = int(Semantic.UNOBSERVED)  # the roadside beyond x = 40 m unseen
    rasters = load_site_rasters(write_raster_site(tmp_path / "smeared", semantic, vectors))

    def north(config: RuleConfig) -> list[np.ndarray]:
        return [
            v.points
            for v in propose_rule_based(rasters, config)
            if v.cls == "boundary" and v.points[:, 1].mean() > 785
        ]

    edge = north(RuleConfig(boundary_source="road_edge"))
    assert len(edge) == 1
    # on the road's edge: between its first row (12.1 m, the rows above are hidden or curb) and the rim above
    np.testing.assert_allclose(edge[0][:, 1], global_xy(0, 12.05)[1], atol=0.03)
    assert edge[0][:, 0].min() < 500.5 and edge[0][:, 0].max() < 500 + 41.1, (
        "no boundary along the unseen roadside"
    )
    curb = north(RuleConfig(boundary_source="curb"))
    assert curb and all(abs(p[:, 1].mean() - global_xy(0, 11.25)[1]) < 0.3 for p in curb), (
        "the curb source follows the middle of the (smeared) curb label"
    )


def test_an_unknown_boundary_source_is_refused() -> None:
    with pytest.raises(ValueError, match="boundary_source"):
        RuleConfig(boundary_source="kerb")  # type: ignore[arg-type]


def test_road_edge_boundaries_run_on_where_the_road_meets_the_sidewalk_without_a_curb_label(
    tmp_path: Path,
) -> None:
    semantic, vectors = drawn_semantic()
    row = pixel(0, 28)[1]
    semantic[row - 1 : row + 1, pixel(10, 0)[0] : pixel(45, 0)[0]] = int(Semantic.BACKGROUND)  # no curb seen
    rasters = load_site_rasters(write_raster_site(tmp_path / "no_curb", semantic, vectors))
    south = [
        v.points
        for v in propose_rule_based(rasters, RuleConfig(boundary_source="road_edge"))
        if v.cls == "boundary" and v.points[:, 1].mean() < 785
    ]
    assert len(south) == 1, "one boundary along the whole road edge"
    assert south[0][:, 0].min() < 501 and south[0][:, 0].max() > 558
    np.testing.assert_allclose(south[0][:, 1], global_xy(0, 28)[1], atol=0.2)


def test_a_boundary_loses_the_hook_round_the_corner_into_unseen_cells() -> None:
    line = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 0.8]])
    np.testing.assert_allclose(trim_hooks(line, 1.5, 45.0), line[:2])
    rounded = np.array([[0.0, 0.0], [10.0, 0.0], [10.3, 0.3], [10.3, 0.6]])  # a hook of two segments
    np.testing.assert_allclose(trim_hooks(rounded, 1.5, 45.0), rounded[:2])
    bend = np.array([[0.0, 0.0], [10.0, 0.0], [14.0, 4.0]])  # a real turn, longer than a hook
    np.testing.assert_allclose(trim_hooks(bend, 1.5, 45.0), bend)


def test_a_divider_runs_on_to_the_edge_of_what_was_seen_but_not_into_a_crossing(tmp_path: Path) -> None:
    semantic, vectors = drawn_semantic()
    semantic[:, pixel(52, 0)[0] :] = int(Semantic.UNOBSERVED)  # nothing seen beyond x = 52 m
    rasters = load_site_rasters(write_raster_site(tmp_path / "cut", semantic, vectors))
    east = [
        v.points for v in propose_rule_based(rasters) if v.cls == "divider" and v.points[:, 0].min() > 530
    ]
    assert len(east) == 1
    assert east[0][:, 0].max() == pytest.approx(500 + 51.9, abs=0.15), "last dash at 49 m carried on to 52 m"
    assert east[0][:, 0].min() == pytest.approx(500 + 37, abs=0.3), "not carried into the crossing"
    unchanged = propose_rule_based(rasters, RuleConfig(extend_to_unseen_m=1.0))
    assert max(v.points[:, 0].max() for v in unchanged if v.cls == "divider") < 500 + 49.5


def test_a_crossing_runs_from_kerb_to_kerb_past_its_outer_stripes(drawn_site: Path) -> None:
    # the drawn stripes span y 12.5-27.5 m between curbs at y 12 and 28 m, and x 30-34 m along the road
    (ring,) = [v.points for v in propose_rule_based(load_site_rasters(drawn_site)) if v.cls == "ped_crossing"]
    ys, xs = ring[:, 1], ring[:, 0]
    assert ys.max() == pytest.approx(global_xy(0, 12)[1], abs=0.2)
    assert ys.min() == pytest.approx(global_xy(0, 28)[1], abs=0.2)
    assert xs.min() == pytest.approx(530, abs=0.2) and xs.max() == pytest.approx(534, abs=0.2), (
        "not along the road"
    )


def test_a_kink_is_dropped_from_a_divider_but_a_gentle_curve_kept() -> None:
    kinked = np.array([[0.0, 0.0], [5.0, 0.0], [5.8, -0.4], [6.6, -0.4], [7.5, 0.0], [20.0, 0.0]])
    np.testing.assert_allclose(drop_kinks(kinked, 10.0), kinked[[0, 1, 4, 5]])
    angles = np.linspace(0.0, 0.6, 6)
    curve = 30.0 * np.column_stack([np.sin(angles), 1 - np.cos(angles)])  # radius 30 m
    np.testing.assert_allclose(drop_kinks(curve, 10.0), curve)
