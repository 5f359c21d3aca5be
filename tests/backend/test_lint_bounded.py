"""Bounded work per request (issue 21, point 3): vertex limits on element writes that name the setting, a site
of 60 dividers x 5,000 vertices that lints once and then per changed element, and a lint budget that answers
with what it has and says how much is pending."""

import dataclasses
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
from fastapi.testclient import TestClient

from app.backend.config import Settings
from app.backend.crud.quality import LintCache, lint_site
from tests.backend_quality.lint_spies import count_calls, refuse_vertex_walks

Headers = dict[str, dict[str, str]]


def line(count: int, y: float, x0: float = 5.0, x1: float = 90.0) -> list[list[float]]:
    """A straight divider of `count` vertices along x at height y."""
    return [[float(x), y] for x in np.linspace(x0, x1, count)]


def probe_bodies(dividers: int = 60, vertices: int = 5000) -> list[dict[str, Any]]:
    """The probe's site: wavy dividers 1.6 m apart across the 100 m test site (neighbours are narrow)."""
    x = np.linspace(0.0, 99.0, vertices)
    return [
        {"class": "divider", "points": np.c_[x, 2.0 + 1.6 * k + 0.2 * np.sin(x / 3.0)].round(4).tolist()}
        for k in range(dividers)
    ]


@pytest.fixture
def settings(settings: Settings, request: pytest.FixtureRequest) -> Settings:
    """The shared test settings with the overrides the test carries (`with_settings`)."""
    overrides: dict[str, Any] = getattr(request.function, "settings", {})
    return dataclasses.replace(settings, **overrides)


def with_settings(**overrides: Any) -> Callable[[Callable[..., None]], Callable[..., None]]:
    """Mark a test with the settings it runs under."""

    def mark(test: Callable[..., None]) -> Callable[..., None]:
        test.settings = overrides  # type: ignore[attr-defined]
        return test

    return mark


def test_limit_settings_are_read_and_checked() -> None:
    environ = {
        "CAMA_MAX_ELEMENT_VERTICES": "500",
        "CAMA_MAX_SITE_VERTICES": "9000",
        "CAMA_LINT_BUDGET_S": "0.5",
    }
    settings = Settings.from_env(environ)
    assert (settings.max_element_vertices, settings.max_site_vertices, settings.lint_budget_s) == (
        500,
        9000,
        0.5,
    )
    with pytest.raises(ValueError, match="CAMA_MAX_SITE_VERTICES"):
        Settings.from_env({"CAMA_MAX_ELEMENT_VERTICES": "500", "CAMA_MAX_SITE_VERTICES": "100"})
    with pytest.raises(ValueError, match="CAMA_LINT_BUDGET_S"):
        Settings(lint_budget_s=-1.0)


def _detail(response: Any) -> str:
    return " ".join(item["msg"] for item in response.json()["detail"])


@with_settings(max_element_vertices=50, max_site_vertices=120)
def test_vertex_limits_refuse_writes_and_name_the_setting(
    client: TestClient, headers: Headers, site_id: int
) -> None:
    url = f"/api/sites/{site_id}/elements"
    lead = headers["lead"]
    too_long = client.post(url, json={"class": "divider", "points": line(51, 10.0)}, headers=lead)
    assert too_long.status_code == 422, too_long.text
    assert "CAMA_MAX_ELEMENT_VERTICES" in _detail(too_long) and "50" in _detail(too_long)
    first = client.post(url, json={"class": "divider", "points": line(50, 10.0)}, headers=lead).json()
    second = client.post(url, json={"class": "divider", "points": line(50, 20.0)}, headers=lead).json()
    third = client.post(url, json={"class": "divider", "points": line(30, 30.0)}, headers=lead)
    assert third.status_code == 422, third.text  # 100 stored + 30 > 120
    assert "CAMA_MAX_SITE_VERTICES" in _detail(third) and "120" in _detail(third)
    bulk = {
        "elements": [
            {"class": "divider", "points": line(10, 40.0)},
            {"class": "divider", "points": line(15, 50.0)},
        ]
    }
    refused = client.post(f"{url}/bulk", json=bulk, headers=lead)
    assert refused.status_code == 422 and "CAMA_MAX_SITE_VERTICES" in _detail(refused)
    grown = client.patch(
        f"{url}/{first['id']}", json={"version": first["version"], "points": line(51, 10.0)}, headers=lead
    )
    assert grown.status_code == 422 and "CAMA_MAX_ELEMENT_VERTICES" in _detail(grown)
    shrunk = client.patch(
        f"{url}/{first['id']}", json={"version": first["version"], "points": line(20, 10.0)}, headers=lead
    )
    assert shrunk.status_code == 200, shrunk.text  # 70 stored: shrinking is always allowed
    regrown = {"version": shrunk.json()["version"], "points": line(50, 10.0)}
    assert client.patch(f"{url}/{first['id']}", json=regrown, headers=lead).status_code == 200  # 100
    fourth = client.post(url, json={"class": "divider", "points": line(21, 30.0)}, headers=lead)
    assert fourth.status_code == 422  # 100 + 21 > 120
    deleted = client.delete(f"{url}/{second['id']}?version={second['version']}", headers=lead)
    assert deleted.status_code == 200, deleted.text  # deleted elements do not count
    assert (
        client.post(url, json={"class": "divider", "points": line(21, 30.0)}, headers=lead).status_code == 201
    )


@with_settings(max_payload_bytes=32 * 1024 * 1024, lint_budget_s=600.0)
def test_probe_site_lints_once_then_per_changed_element(
    client: TestClient, headers: Headers, site_id: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    url = f"/api/sites/{site_id}"
    created = client.post(f"{url}/elements/bulk", json={"elements": probe_bodies()}, headers=headers["lead"])
    assert created.status_code == 201, created.text[:500]
    ids = [element["id"] for element in created.json()]
    refuse_vertex_walks(monkeypatch)
    own, pairs = (
        count_calls(monkeypatch, "self_intersection_of"),
        count_calls(monkeypatch, "spacing_candidate_of"),
    )

    report = client.get(f"{url}/lint", headers=headers["annotator"]).json()
    assert (report["element_count"], report["pending_elements"]) == (60, 0)
    assert [f["element_ids"] for f in report["findings"]] == [
        [a, b] for a, b in zip(ids, ids[1:], strict=False)
    ]
    assert {f["code"] for f in report["findings"]} == {"divider_spacing_narrow"}
    assert own[0] == 60 and 0 < pairs[0] < 60 * 59 // 2  # neighbours within reach only, not every pair

    own[0] = pairs[0] = 0
    assert client.get(f"{url}/lint", headers=headers["lead"]).json() == report  # unchanged: the same report
    assert (
        client.get(f"/api/sites/{site_id}/queue/review", headers=headers["lead"]).status_code == 200
    )  # the queues' lint
    assert own[0] == pairs[0] == 0

    moved = created.json()[29]
    body = {"version": moved["version"], "points": [[x, y + 0.3] for x, y in moved["points"]]}
    assert (
        client.patch(f"{url}/elements/{moved['id']}", json=body, headers=headers["lead"]).status_code == 200
    )
    after = client.get(f"{url}/lint", headers=headers["annotator"]).json()
    assert own[0] == 1 and 0 < pairs[0] <= 8  # the moved divider, and its four neighbours on each side
    work = client.app.state.lint_cache.last_work(site_id)  # type: ignore[attr-defined]
    assert (work.elements, work.pairs, work.pending) == (1, pairs[0], [])
    assert len(after["findings"]) == 59
    with client.app.state.sessionmaker() as session:  # type: ignore[attr-defined]
        fresh = lint_site(session=session, site_id=site_id, cache=LintCache())
    assert after == fresh.model_dump(mode="json")


@with_settings(lint_budget_s=0.0)
def test_lint_budget_answers_with_what_it_has_and_goes_on(
    client: TestClient, headers: Headers, site_id: int
) -> None:
    url = f"/api/sites/{site_id}"
    bodies = [{"class": "divider", "points": line(3, y, 10.0, 30.0)} for y in (10.0, 12.0, 40.0, 70.0)]
    assert (
        client.post(f"{url}/elements/bulk", json={"elements": bodies}, headers=headers["lead"]).status_code
        == 201
    )
    pending = []
    for _ in range(4):
        report = client.get(f"{url}/lint", headers=headers["annotator"]).json()
        assert report["element_count"] == 4
        pending.append(report["pending_elements"])
    assert pending == [3, 2, 1, 0]  # a budget of 0 lints one element per request
    with client.app.state.sessionmaker() as session:  # type: ignore[attr-defined]
        full = lint_site(session=session, site_id=site_id, cache=LintCache())
    assert report == full.model_dump(mode="json")
    assert any(f["code"] == "divider_spacing_narrow" for f in report["findings"])
