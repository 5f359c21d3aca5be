"""Map lint rules on hand-made layouts with known answers."""

import numpy as np
import pytest
from shapely.geometry import box

from annotations.schema import MapElement
from app.backend.quality import (
    ElementView,
    LintConfig,
    find_bad_crosswalks,
    find_broken_boundaries,
    find_crossing_dividers,
    find_dangling_divider_ends,
    find_divider_spacing,
    find_self_intersections,
    lint,
)

REGION = box(0.0, -5.0, 50.0, 15.0)
CONFIG = LintConfig()


def view(element_id: str, cls: str, points: list[tuple[float, float]]) -> ElementView:
    """An element view from a list of points."""
    return ElementView(id=element_id, cls=cls, points=np.asarray(points, dtype=float))


def clean_layout() -> list[MapElement]:
    """Two parallel dividers 3.5 m apart between two boundaries, spanning the region."""
    lines = {
        "b0": ("boundary", 0.0),
        "d1": ("divider", 3.5),
        "d2": ("divider", 7.0),
        "b3": ("boundary", 10.5),
    }
    return [
        MapElement(id=key, cls=cls, points_2d=[(0.0, y), (25.0, y), (50.0, y)], source="human")
        for key, (cls, y) in lines.items()
    ]


def codes(findings: list) -> list[str]:
    """The codes of some findings, sorted."""
    return sorted(finding.code for finding in findings)


def test_clean_layout_has_no_findings() -> None:
    assert lint(clean_layout(), region=REGION) == []
    assert lint(clean_layout(), region=REGION, config=LintConfig(window_size_m=25.0)) == []


def test_divider_ends_at_region_border_dangle_without_region() -> None:
    assert codes(lint(clean_layout())) == ["dangling_divider_end"] * 4


def test_dangling_divider_ends_found_in_the_open() -> None:
    views = [
        view("d", "divider", [(10.0, 3.5), (40.0, 3.5)]),
        view("b", "boundary", [(0.0, 0.0), (50.0, 0.0)]),
    ]
    findings = find_dangling_divider_ends(views, CONFIG, REGION)
    assert [finding.location_xy for finding in findings] == [(10.0, 3.5), (40.0, 3.5)]
    assert all(finding.element_ids == ("d",) for finding in findings)


def test_divider_end_near_boundary_crosswalk_or_other_end_is_not_dangling() -> None:
    views = [
        view("b", "boundary", [(-10.0, 0.0), (60.0, 0.0)]),
        view("d1", "divider", [(20.0, 0.5), (30.0, 3.5)]),
        view("d2", "divider", [(30.5, 3.5), (39.0, 3.5)]),
        view("c", "ped_crossing", [(40.0, 1.0), (44.0, 1.0), (44.0, 8.0), (40.0, 8.0), (40.0, 1.0)]),
    ]
    assert find_dangling_divider_ends(views, CONFIG) == []


def test_self_intersection_located_at_the_crossing() -> None:
    views = [view("d", "divider", [(0.0, 0.0), (10.0, 0.0), (10.0, 5.0), (5.0, -5.0)])]
    (finding,) = find_self_intersections(views, CONFIG)
    assert finding.code == "self_intersection" and finding.severity == "error"
    assert finding.location_xy == pytest.approx((7.5, 0.0))
    assert (
        find_self_intersections([view("s", "boundary", [(0.0, 0.0), (5.0, 1.0), (9.0, 0.0)])], CONFIG) == []
    )


def test_crossing_dividers_found_but_not_joins_at_ends() -> None:
    crossing = [
        view("a", "divider", [(0.0, 0.0), (10.0, 10.0)]),
        view("b", "divider", [(0.0, 10.0), (10.0, 0.0)]),
    ]
    (finding,) = find_crossing_dividers(crossing, CONFIG)
    assert finding.element_ids == ("a", "b")
    assert finding.location_xy == pytest.approx((5.0, 5.0))
    joined = [
        view("a", "divider", [(0.0, 0.0), (10.0, 0.0)]),
        view("b", "divider", [(10.0, 0.0), (10.0, 10.0)]),
        view("t", "divider", [(5.0, 0.0), (5.0, -10.0)]),
    ]
    assert find_crossing_dividers(joined, CONFIG) == []


def parallel(*offsets_m: float) -> list[ElementView]:
    """Straight dividers along x at the given y offsets."""
    return [view(f"d{k}", "divider", [(0.0, y), (50.0, y)]) for k, y in enumerate(offsets_m)]


def test_divider_spacing_narrow_and_missing() -> None:
    (narrow,) = find_divider_spacing(parallel(0.0, 2.0), CONFIG)
    assert narrow.code == "divider_spacing_narrow"
    assert narrow.location_xy[1] == pytest.approx(1.0)
    (missing,) = find_divider_spacing(parallel(0.0, 5.0), CONFIG)
    assert missing.code == "divider_spacing_missing"
    assert find_divider_spacing(parallel(0.0, 3.5, 7.0), CONFIG) == []


def test_divider_spacing_skips_pairs_with_a_divider_between_and_non_parallel_pairs() -> None:
    assert find_divider_spacing(parallel(0.0, 2.6, 5.2), CONFIG) == []
    skewed = [
        view("a", "divider", [(0.0, 0.0), (50.0, 0.0)]),
        view("b", "divider", [(0.0, 2.0), (50.0, 32.0)]),
    ]
    assert find_divider_spacing(skewed, CONFIG) == []


def test_spacing_thresholds_are_configurable() -> None:
    assert find_divider_spacing(parallel(0.0, 2.0), LintConfig(min_spacing_m=1.5)) == []


def test_boundary_broken_at_window_border() -> None:
    config = LintConfig(window_size_m=25.0)
    broken = [
        view("b1", "boundary", [(0.0, 10.0), (24.8, 10.0)]),
        view("b2", "boundary", [(25.2, 10.0), (50.0, 10.0)]),
    ]
    (finding,) = find_broken_boundaries(broken, config)
    assert finding.element_ids == ("b1", "b2")
    assert finding.location_xy == pytest.approx((25.0, 10.0))
    away = [
        view("b1", "boundary", [(0.0, 10.0), (12.0, 10.0)]),
        view("b2", "boundary", [(12.4, 10.0), (20.0, 10.0)]),
    ]
    assert find_broken_boundaries(away, config) == []
    assert find_broken_boundaries(broken, CONFIG) == []  # no window size: rule off


def test_bad_crosswalks() -> None:
    crosswalks = [
        view("open", "ped_crossing", [(0.0, 0.0), (4.0, 0.0), (4.0, 6.0), (0.0, 6.0)]),
        view("bowtie", "ped_crossing", [(0.0, 0.0), (4.0, 6.0), (4.0, 0.0), (0.0, 6.0), (0.0, 0.0)]),
        view("good", "ped_crossing", [(0.0, 0.0), (4.0, 0.0), (4.0, 6.0), (0.0, 6.0), (0.0, 0.0)]),
    ]
    findings = find_bad_crosswalks(crosswalks, CONFIG)
    assert [(f.code, f.element_ids) for f in findings] == [
        ("crosswalk_not_closed", ("open",)),
        ("crosswalk_not_simple", ("bowtie",)),
    ]


def test_config_and_view_validation() -> None:
    with pytest.raises(ValueError, match="min_spacing_m"):
        LintConfig(min_spacing_m=0.0)
    with pytest.raises(ValueError, match="missing_gap_m"):
        LintConfig(missing_gap_m=(6.0, 4.5))
    with pytest.raises(ValueError, match="'x'"):
        view("x", "divider", [(0.0, float("nan")), (1.0, 1.0)])


def test_lint_scales_to_thousands_of_elements() -> None:
    views = [
        view(f"d{row}_{col}", "divider", [(col * 60.0, row * 3.5), (col * 60.0 + 50.0, row * 3.5)])
        for row in range(40)
        for col in range(50)
    ]
    findings = lint(views)
    assert codes(findings) == ["dangling_divider_end"] * (2 * len(views))


def test_lint_of_no_elements_or_one_element_does_not_crash():
    """Found by the schemathesis run: an empty neighbour query used to raise inside STRtree."""
    assert lint([]) == []
    single = [ElementView(id="only", cls="divider", points=np.array([[0.0, 0.0], [5.0, 0.0]]))]
    codes = {finding.code for finding in lint(single, region=box(-10, -10, 10, 10))}
    assert codes == {"dangling_divider_end"}
