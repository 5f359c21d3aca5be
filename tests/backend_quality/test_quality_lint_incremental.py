"""`SiteLint` keeps a site's lint up to date element by element (issue 21, point 3): after any sequence of edits
it equals a lint from scratch, an edit re-lints only the changed element and its neighbours, and a site of 60
dividers x 5,000 vertices lints without walking every vertex for every sample."""

from typing import Any

import numpy as np
import pytest
from shapely.geometry import box

from app.backend.quality import ElementView, LintConfig, LintFinding, SiteLint, lint
from tests.backend_quality.lint_spies import count_calls, refuse_vertex_walks

REGION = box(0.0, 0.0, 100.0, 100.0)


def probe_site(dividers: int = 60, vertices: int = 5000) -> list[ElementView]:
    """The probe's site: long wavy dividers 1.6 m apart across a 100 m site (each pair of neighbours narrow)."""
    x = np.linspace(0.0, 100.0, vertices)
    return [
        ElementView(id=str(k + 1), cls="divider", points=np.c_[x, 2.0 + 1.6 * k + 0.2 * np.sin(x / 3.0)])
        for k in range(dividers)
    ]


def _random_element(rng: np.random.Generator, element_id: str) -> ElementView:
    """A divider, boundary or crosswalk somewhere in a 60 m square, often near others."""
    x0, y0 = rng.uniform(0.0, 60.0, 2)
    cls = str(rng.choice(["divider", "divider", "divider", "boundary", "ped_crossing"]))
    if cls == "ped_crossing":
        w, h = rng.uniform(2.0, 6.0, 2)
        ring = [[x0, y0], [x0 + w, y0], [x0 + w, y0 + h], [x0, y0 + h], [x0, y0]]
        return ElementView(id=element_id, cls=cls, points=np.asarray(ring))
    count, length_m = int(rng.integers(2, 40)), rng.uniform(3.0, 40.0)
    t = np.linspace(0.0, length_m, count)
    angle = rng.choice([0.0, np.pi / 2, rng.uniform(0.0, np.pi)])
    wiggle = rng.choice([0.0, 1.5]) * np.sin(t / 2.0)
    points = np.c_[
        x0 + t * np.cos(angle) - wiggle * np.sin(angle), y0 + t * np.sin(angle) + wiggle * np.cos(angle)
    ]
    return ElementView(id=element_id, cls=cls, points=points)


def _key(findings: list[LintFinding]) -> list[tuple[Any, ...]]:
    return sorted(
        (f.code, f.element_ids, round(f.location_xy[0], 9), round(f.location_xy[1], 9)) for f in findings
    )


def test_incremental_lint_equals_a_lint_from_scratch_after_every_edit() -> None:
    rng = np.random.default_rng(3)
    config = LintConfig(window_size_m=25.0)
    live = {str(k): _random_element(rng, str(k)) for k in range(40)}
    state = SiteLint(config=config, region=box(0.0, 0.0, 60.0, 60.0), rank=int)
    state.update(live.values())
    next_id = len(live)
    for step in range(40):
        action = step % 4
        if action in (0, 1):  # move or reshape one
            element_id = str(rng.choice(sorted(live)))
            live[element_id] = _random_element(rng, element_id)
            state.update([live[element_id]])
        elif action == 2:  # delete one
            element_id = str(rng.choice(sorted(live)))
            del live[element_id]
            state.update([], removed=[element_id])
        else:  # draw two
            drawn = [_random_element(rng, str(next_id)), _random_element(rng, str(next_id + 1))]
            next_id += 2
            live.update((view.id, view) for view in drawn)
            state.update(drawn)
        ordered = sorted(live.values(), key=lambda view: int(view.id))
        expected = lint(ordered, config=config, region=box(0.0, 0.0, 60.0, 60.0))
        assert _key(state.findings()) == _key(expected), f"step {step}"
        assert state.findings() == expected, f"step {step}: same findings in the same order"


def test_probe_site_lints_and_an_edit_relints_only_the_changed_element(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    refuse_vertex_walks(monkeypatch)
    own, spacing = (
        count_calls(monkeypatch, "self_intersection_of"),
        count_calls(monkeypatch, "spacing_candidate_of"),
    )
    views = probe_site()
    state = SiteLint(region=REGION, rank=int)
    work = state.update(views)
    findings = state.findings()
    assert {f.code for f in findings} == {"divider_spacing_narrow"}
    assert [f.element_ids for f in findings] == [(str(k), str(k + 1)) for k in range(1, 60)]
    assert (work.elements, own[0]) == (60, 60)
    assert spacing[0] == work.pairs < 60 * 59 // 2  # neighbours within reach only, not every pair

    moved = ElementView(id="30", cls="divider", points=views[29].points + [0.0, 0.3])
    own[0] = spacing[0] = 0
    work = state.update([moved])
    assert (work.elements, own[0]) == (1, 1)
    assert spacing[0] == work.pairs <= 8  # dividers 1.6 m apart: four on each side within 7 m
    assert work.divider_ends <= 3
    assert len(state.findings()) == 59


def test_an_update_past_its_deadline_leaves_the_rest_pending_and_stays_consistent() -> None:
    views = probe_site(dividers=6, vertices=50)
    state = SiteLint(region=REGION, rank=int)
    work = state.update(views, deadline=0.0)  # long passed: one batch (one element), then stop
    assert work.elements == 1 and work.pending == [view.id for view in views[1:]]
    assert set(state.views) == {"1"}
    while work.pending:
        work = state.update([view for view in views if view.id in work.pending], deadline=0.0)
    assert state.findings() == lint(views, region=REGION)


def test_repeated_ids_in_one_update_are_refused() -> None:
    view = probe_site(dividers=1, vertices=5)[0]
    with pytest.raises(ValueError, match="unique"):
        SiteLint().update([view, view])
