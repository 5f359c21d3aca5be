"""Elements, bad input, version conflicts, review transitions, history and restore through the HTTP API."""

from collections.abc import Callable
from typing import Any

import pytest
from fastapi.testclient import TestClient

from tests.backend.backend_helpers import crosswalk, divider

Headers = dict[str, dict[str, str]]
MakeElement = Callable[..., dict[str, Any]]


def test_crud_and_bbox(client: TestClient, headers: Headers, site_id: int, make_element: MakeElement) -> None:
    a = make_element(divider(10, 10))
    b = make_element(crosswalk(60, 60))
    assert a["version"] == 1 and a["state"] == "proposed" and a["author"] == "annotator"
    base = f"/api/sites/{site_id}/elements"
    got = client.get(f"{base}/{a['id']}", headers=headers["lead"]).json()
    assert got["class"] == "divider" and got["points"][0] == [10.0, 10.0]
    near_a = client.get(base, params={"bbox": "0,0,20,20"}, headers=headers["lead"]).json()
    assert [e["id"] for e in near_a] == [a["id"]]
    by_class = client.get(base, params={"class": "ped_crossing"}, headers=headers["lead"]).json()
    assert [e["id"] for e in by_class] == [b["id"]]
    assert client.get(base, params={"bbox": "1,2,3"}, headers=headers["lead"]).status_code == 422
    changed = client.patch(
        f"{base}/{a['id']}", json={"version": 1, "points": [[11, 10], [20, 10]]}, headers=headers["annotator"]
    )
    assert changed.status_code == 200, changed.text
    assert changed.json()["version"] == 2 and changed.json()["points"] == [[11.0, 10.0], [20.0, 10.0]]
    assert client.get(f"{base}/999", headers=headers["lead"]).status_code == 404
    assert client.get("/api/sites/999/elements", headers=headers["lead"]).status_code == 404


def test_bulk_proposals(client: TestClient, headers: Headers, site_id: int) -> None:
    elements = [divider(5 + i, 5 + i, source="proposal", confidence=0.1 * i) for i in range(5)]
    response = client.post(
        f"/api/sites/{site_id}/elements/bulk", json={"elements": elements}, headers=headers["lead"]
    )
    assert response.status_code == 201, response.text
    assert len(response.json()) == 5 and {e["source"] for e in response.json()} == {"proposal"}
    bad = [
        divider(5, 5, source="proposal", confidence=0.5),
        divider(500, 500, source="proposal", confidence=0.5),
    ]
    response = client.post(
        f"/api/sites/{site_id}/elements/bulk", json={"elements": bad}, headers=headers["lead"]
    )
    assert response.status_code == 422 and "elements.1.points" in response.text
    listed = client.get(f"/api/sites/{site_id}/elements", headers=headers["lead"]).json()
    assert len(listed) == 5  # all or none
    no_conf = {"elements": [divider(source="proposal")]}
    response = client.post(f"/api/sites/{site_id}/elements/bulk", json=no_conf, headers=headers["lead"])
    assert response.status_code == 422 and "confidence" in response.text


def test_a_proposal_names_the_model_that_made_it(client: TestClient, headers: Headers, site_id: int) -> None:
    named = {"elements": [{**divider(5, 5, source="proposal", confidence=0.8), "model": "vma-v0003"}]}
    response = client.post(f"/api/sites/{site_id}/elements/bulk", json=named, headers=headers["lead"])
    assert response.status_code == 201, response.text
    (element,) = response.json()
    assert element["proposed_by"] == "vma-v0003" and element["author"] == "lead"
    base = f"/api/sites/{site_id}/elements/{element['id']}"
    fixed = {"points": [[6.0, 5.0], [20.0, 5.0]], "version": 1}
    assert client.patch(base, json=fixed, headers=headers["lead"]).status_code == 200
    assert (
        client.get(base, headers=headers["lead"]).json()["proposed_by"] == "vma-v0003"
    )  # kept through edits
    drawn = {**divider(7, 7), "model": "vma-v0003"}
    response = client.post(f"/api/sites/{site_id}/elements", json=drawn, headers=headers["lead"])
    assert response.status_code == 422 and "model: only a proposal" in response.text
    plain = client.post(f"/api/sites/{site_id}/elements", json=divider(8, 8), headers=headers["lead"])
    assert plain.json()["proposed_by"] is None


@pytest.mark.parametrize(
    "body, needle",
    [
        ({"class": "tree", "points": [[1, 1], [2, 2]]}, "class"),
        ({"class": "divider", "points": [[1, 1]]}, "at least 2 points"),
        ({"class": "ped_crossing", "points": [[0, 0], [4, 4], [4, 0], [0, 4], [0, 0]]}, "crosses itself"),
        ({"class": "ped_crossing", "points": [[0, 0], [4, 0], [4, 4], [0, 4]]}, "not closed"),
        ({"class": "divider", "points": [[10, 10], [900, 10]]}, "outside the site extent"),
        ({"class": "divider", "points": [[10, 10], [20, 10]], "extra": 1}, "extra"),
    ],
)
def test_bad_element_is_422(
    client: TestClient, headers: Headers, site_id: int, body: Any, needle: str
) -> None:
    response = client.post(f"/api/sites/{site_id}/elements", json=body, headers=headers["annotator"])
    assert response.status_code == 422, response.text
    assert needle in response.text


@pytest.mark.parametrize("token", ["NaN", "Infinity", "-Infinity"])
def test_non_finite_rejected_at_parse(client: TestClient, headers: Headers, site_id: int, token: str) -> None:
    raw = '{"class": "divider", "points": [[1, 1], [' + token + ", 2]]}"
    hdrs = {**headers["annotator"], "Content-Type": "application/json"}
    response = client.post(f"/api/sites/{site_id}/elements", content=raw, headers=hdrs)
    assert response.status_code == 422, response.text
    assert "finite" in response.text


def test_oversized_payload_is_413(client: TestClient, headers: Headers, site_id: int) -> None:
    points = [[10 + i * 1e-3, 10.0] for i in range(20_000)]
    body = {"class": "divider", "points": points}
    response = client.post(f"/api/sites/{site_id}/elements", json=body, headers=headers["annotator"])
    assert response.status_code == 413

    def stream() -> Any:
        for _ in range(100):
            yield b"x" * 1024

    response = client.post(f"/api/sites/{site_id}/elements", content=stream(), headers=headers["annotator"])
    assert response.status_code == 413


def test_stale_version_is_409_with_current(
    client: TestClient, headers: Headers, site_id: int, make_element: MakeElement
) -> None:
    element = make_element()
    url = f"/api/sites/{site_id}/elements/{element['id']}"
    assert (
        client.patch(url, json={"version": 1, "confidence": 0.9}, headers=headers["lead"]).status_code == 200
    )
    stale = client.patch(url, json={"version": 1, "points": [[1, 1], [2, 2]]}, headers=headers["annotator"])
    assert stale.status_code == 409
    assert stale.json()["current"]["version"] == 2 and stale.json()["current"]["confidence"] == 0.9
    assert client.delete(url, params={"version": 1}, headers=headers["annotator"]).status_code == 409


def test_update_validates_merged_element(
    client: TestClient, headers: Headers, site_id: int, make_element: MakeElement
) -> None:
    element = make_element()
    url = f"/api/sites/{site_id}/elements/{element['id']}"
    response = client.patch(url, json={"version": 1, "class": "ped_crossing"}, headers=headers["annotator"])
    assert response.status_code == 422 and "not closed" in response.text


def review(client: TestClient, url: str, state: str, version: int, who: dict[str, str]) -> Any:
    """Post a review transition."""
    return client.post(f"{url}/review", json={"state": state, "version": version}, headers=who)


def test_review_transitions(
    client: TestClient, headers: Headers, site_id: int, make_element: MakeElement
) -> None:
    url = f"/api/sites/{site_id}/elements/{make_element()['id']}"
    assert review(client, url, "approved", 1, headers["annotator"]).status_code == 403
    assert review(client, url, "approved", 1, headers["lead"]).status_code == 409  # proposed -> approved
    assert review(client, url, "accepted", 1, headers["annotator"]).json()["state"] == "accepted"
    assert review(client, url, "rejected", 2, headers["annotator"]).status_code == 409
    assert review(client, url, "returned", 2, headers["lead"]).json()["state"] == "returned"
    assert review(client, url, "fixed", 3, headers["annotator"]).json()["state"] == "fixed"
    approved = review(client, url, "approved", 4, headers["lead"])
    assert approved.json()["state"] == "approved" and approved.json()["version"] == 5
    assert review(client, url, "bogus", 5, headers["lead"]).status_code == 422
    assert review(client, url, "accepted", 4, headers["lead"]).status_code == 409  # stale


def test_history_restore_and_soft_delete(
    client: TestClient, headers: Headers, site_id: int, make_element: MakeElement
) -> None:
    url = f"/api/sites/{site_id}/elements/{make_element()['id']}"
    client.patch(url, json={"version": 1, "points": [[30, 30], [40, 30]]}, headers=headers["annotator"])
    deleted = client.delete(url, params={"version": 2}, headers=headers["annotator"])
    assert deleted.status_code == 200 and deleted.json()["deleted"] is True
    assert client.get(f"/api/sites/{site_id}/elements", headers=headers["lead"]).json() == []
    listed = client.get(f"/api/sites/{site_id}/elements?include_deleted=true", headers=headers["lead"]).json()
    assert len(listed) == 1
    history = client.get(f"{url}/history", headers=headers["lead"]).json()
    assert [(h["version"], h["action"]) for h in history] == [(1, "create"), (2, "update"), (3, "delete")]
    assert history[1]["before"]["points"][0] == [10.0, 10.0] and history[1]["after"]["points"][0] == [
        30.0,
        30.0,
    ]
    assert all(h["username"] == "annotator" for h in history)
    restored = client.post(f"{url}/history/1/restore", json={"version": 3}, headers=headers["lead"])
    assert restored.status_code == 200, restored.text
    body = restored.json()
    assert body["version"] == 4 and body["deleted"] is False and body["points"][0] == [10.0, 10.0]
    assert (
        client.post(f"{url}/history/9/restore", json={"version": 4}, headers=headers["lead"]).status_code
        == 404
    )
    assert (
        client.post(f"{url}/history/1/restore", json={"version": 3}, headers=headers["lead"]).status_code
        == 409
    )
    assert len(client.get(f"{url}/history", headers=headers["lead"]).json()) == 4


def test_only_a_lead_restores_across_a_leads_decision(
    client: TestClient, headers: Headers, site_id: int, make_element: MakeElement
) -> None:
    url = f"/api/sites/{site_id}/elements/{make_element()['id']}"
    assert review(client, url, "accepted", 1, headers["annotator"]).status_code == 200
    undone = client.post(f"{url}/history/1/restore", json={"version": 2}, headers=headers["annotator"])
    assert undone.status_code == 200, undone.text  # an annotator may undo their own verdict
    assert review(client, url, "accepted", 3, headers["annotator"]).status_code == 200
    assert review(client, url, "approved", 4, headers["lead"]).status_code == 200
    refused = client.post(f"{url}/history/4/restore", json={"version": 5}, headers=headers["annotator"])
    assert refused.status_code == 403 and "lead" in refused.json()["detail"]
    by_lead = client.post(f"{url}/history/4/restore", json={"version": 5}, headers=headers["lead"])
    assert by_lead.status_code == 200 and by_lead.json()["state"] == "accepted"
    back = client.post(f"{url}/history/5/restore", json={"version": 6}, headers=headers["annotator"])
    assert back.status_code == 403  # nor bring an approval back
