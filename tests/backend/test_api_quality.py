"""Quality endpoints through HTTP: lint (site, bbox, per element, cached), proposal diffs, figures and roles."""

from collections.abc import Callable
from typing import Any

import pytest
from fastapi.testclient import TestClient

from tests.backend.backend_helpers import divider

Headers = dict[str, dict[str, str]]
MakeElement = Callable[..., dict[str, Any]]


def _codes(report: dict[str, Any]) -> set[str]:
    return {finding["code"] for finding in report["findings"]}


def _proposals(
    client: TestClient, headers: Headers, site_id: int, *bodies: dict[str, Any]
) -> list[dict[str, Any]]:
    response = client.post(
        f"/api/sites/{site_id}/elements/bulk",
        json={"elements": [{**body, "source": "proposal", "confidence": 0.5} for body in bodies]},
        headers=headers["lead"],
    )
    assert response.status_code == 201, response.text
    return list(response.json())


def _review(client: TestClient, headers: Headers, site_id: int, element: dict[str, Any], state: str) -> None:
    response = client.post(
        f"/api/sites/{site_id}/elements/{element['id']}/review",
        json={"state": state, "version": element["version"]},
        headers=headers["annotator"],
    )
    assert response.status_code == 200, response.text


def _move(
    client: TestClient, headers: Headers, site_id: int, element: dict[str, Any], dy: float
) -> dict[str, Any]:
    points = [[x, y + dy] for x, y in element["points"]]
    response = client.patch(
        f"/api/sites/{site_id}/elements/{element['id']}",
        json={"version": element["version"], "points": points},
        headers=headers["annotator"],
    )
    assert response.status_code == 200, response.text
    return dict(response.json())


def test_lint_finds_crossing_dividers_and_follows_edits(
    client: TestClient, headers: Headers, site_id: int, make_element: MakeElement
) -> None:
    first = make_element(divider(10.0, 10.0))
    crossing = make_element({"class": "divider", "points": [[15.0, 5.0], [15.0, 15.0]]})
    url = f"/api/sites/{site_id}/lint"
    report = client.get(url, headers=headers["annotator"]).json()
    assert report["element_count"] == 2
    assert "crossing_dividers" in _codes(report)
    crossing_ids = [f["element_ids"] for f in report["findings"] if f["code"] == "crossing_dividers"]
    assert sorted(crossing_ids[0]) == sorted([first["id"], crossing["id"]])
    assert client.get(url, headers=headers["lead"]).json() == report  # cached, same answer

    moved = _move(client, headers, site_id, crossing, 50.0)  # the save: lint of the element changes
    after = client.get(f"/api/sites/{site_id}/elements/{moved['id']}/lint", headers=headers["annotator"])
    assert after.status_code == 200, after.text
    assert "crossing_dividers" not in {finding["code"] for finding in after.json()}
    assert all(moved["id"] in finding["element_ids"] for finding in after.json())
    assert "crossing_dividers" not in _codes(client.get(url, headers=headers["annotator"]).json())


def test_lint_on_demand_with_bbox(
    client: TestClient, headers: Headers, site_id: int, make_element: MakeElement
) -> None:
    make_element(divider(10.0, 10.0))
    make_element(divider(60.0, 60.0))
    url = f"/api/sites/{site_id}/lint"
    everything = client.post(url, json={}, headers=headers["annotator"]).json()
    near = client.post(url, json={"bbox": [0, 0, 30, 30]}, headers=headers["annotator"])
    assert near.status_code == 200, near.text
    assert 0 < len(near.json()["findings"]) < len(everything["findings"])
    assert all(0 <= f["location_xy"][0] <= 30 for f in near.json()["findings"])


@pytest.mark.parametrize("bbox", [[30, 0, 0, 30], [0, 0, 1], ["a", 0, 1, 1], [0, 0, "inf", 1]])
def test_lint_bad_bbox_is_422(client: TestClient, headers: Headers, site_id: int, bbox: list[Any]) -> None:
    response = client.post(f"/api/sites/{site_id}/lint", json={"bbox": bbox}, headers=headers["annotator"])
    assert response.status_code == 422, response.text


def test_lint_unknown_site_or_element_404(client: TestClient, headers: Headers, site_id: int) -> None:
    assert client.get("/api/sites/999/lint", headers=headers["annotator"]).status_code == 404
    assert client.post("/api/sites/999/lint", json={}, headers=headers["annotator"]).status_code == 404
    missing = client.get(f"/api/sites/{site_id}/elements/999/lint", headers=headers["annotator"])
    assert missing.status_code == 404
    assert client.get(f"/api/sites/{site_id}/lint").status_code == 401


def test_element_diff_of_a_fixed_proposal(client: TestClient, headers: Headers, site_id: int) -> None:
    (proposal,) = _proposals(client, headers, site_id, divider(10.0, 10.0))
    url = f"/api/sites/{site_id}/elements/{proposal['id']}/diff"
    untouched = client.get(url, headers=headers["annotator"]).json()
    assert untouched["unchanged"] is True and untouched["chamfer_m"] == 0.0
    _move(client, headers, site_id, proposal, 0.5)
    diff = client.get(url, headers=headers["annotator"]).json()
    assert diff["unchanged"] is False
    assert diff["vertices_moved"] == 3 and diff["vertices_added"] == 0 and diff["vertices_removed"] == 0
    assert diff["mean_displacement_m"] == pytest.approx(0.5)
    assert diff["chamfer_m"] == pytest.approx(0.5, abs=0.05)


def test_diff_of_hand_drawn_element_is_404(
    client: TestClient, headers: Headers, site_id: int, make_element: MakeElement
) -> None:
    element = make_element()
    response = client.get(f"/api/sites/{site_id}/elements/{element['id']}/diff", headers=headers["annotator"])
    assert response.status_code == 404
    assert "no proposal" in response.json()["detail"]
    assert (
        client.get(f"/api/sites/{site_id}/elements/999/diff", headers=headers["annotator"]).status_code == 404
    )


def test_diff_summary_per_class(client: TestClient, headers: Headers, site_id: int) -> None:
    kept, fixed, pending = _proposals(
        client, headers, site_id, divider(10.0, 10.0), divider(10.0, 30.0), divider(10.0, 50.0)
    )
    _review(client, headers, site_id, kept, "accepted")
    _review(client, headers, site_id, _move(client, headers, site_id, fixed, 1.0), "fixed")
    response = client.get(f"/api/sites/{site_id}/diffs", headers=headers["annotator"])
    assert response.status_code == 200, response.text
    (row,) = response.json()
    assert row["class"] == "divider" and row["elements"] == 2 and row["unchanged"] == 1
    assert row["vertices_moved"] == 3
    assert row["mean_chamfer_m"] == pytest.approx(0.5, abs=0.05)
    assert client.get("/api/sites/999/diffs", headers=headers["annotator"]).status_code == 404


def test_figures_per_annotator_and_class(
    client: TestClient, headers: Headers, site_id: int, make_element: MakeElement
) -> None:
    kept, fixed, dropped = _proposals(
        client, headers, site_id, divider(10.0, 10.0), divider(10.0, 30.0), divider(10.0, 50.0)
    )
    _review(client, headers, site_id, kept, "accepted")
    _review(client, headers, site_id, _move(client, headers, site_id, fixed, 1.0), "fixed")
    _review(client, headers, site_id, dropped, "rejected")
    make_element(divider(60.0, 60.0))
    response = client.get(f"/api/sites/{site_id}/figures", headers=headers["lead"])
    assert response.status_code == 200, response.text
    rows = {(row["author"], row["class"]): row for row in response.json()}
    assert set(rows) == {("annotator", "all"), ("annotator", "divider")}
    row = rows[("annotator", "divider")]
    assert row["items_handled"] == 4 and row["proposals_reviewed"] == 3
    assert row["accepted_unchanged"] == 1 and row["fixes"] == 1
    assert row["mean_fix_displacement_m"] == pytest.approx(1.0)
    assert client.get(f"/api/sites/{site_id}/figures", headers=headers["admin"]).status_code == 200


def test_figures_are_for_leads_only(client: TestClient, headers: Headers, site_id: int) -> None:
    assert client.get(f"/api/sites/{site_id}/figures", headers=headers["annotator"]).status_code == 403
    assert client.get(f"/api/sites/{site_id}/figures").status_code == 401
    assert client.get("/api/sites/999/figures", headers=headers["lead"]).status_code == 404
