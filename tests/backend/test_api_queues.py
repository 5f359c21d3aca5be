"""Review queue order and filters, work-item leases (distinct, concurrent, expiring), returned work first."""

import threading
from datetime import timedelta
from typing import Any

import pytest
from fastapi.testclient import TestClient

from app.backend.clock import utc_now
from app.backend.crud import leases
from app.backend.schemas_review import DEFAULT_LEASE_S
from tests.backend.backend_helpers import PASSWORD, crosswalk, divider, login

Headers = dict[str, dict[str, str]]


def add_annotator(client: TestClient, headers: Headers, name: str) -> dict[str, str]:
    """Create another annotator and return its auth headers."""
    body = {"username": name, "password": PASSWORD, "role": "annotator"}
    response = client.post("/api/users", json=body, headers=headers["admin"])
    assert response.status_code == 201, response.text
    return login(client, name)


def load_proposals(client: TestClient, headers: Headers, site_id: int, confidences: list[float]) -> list[int]:
    """Bulk-load divider proposals with these confidences; their ids in the same order."""
    elements = [
        divider(5 + 3 * i, 5 + 3 * i, source="proposal", confidence=c) for i, c in enumerate(confidences)
    ]
    response = client.post(
        f"/api/sites/{site_id}/elements/bulk", json={"elements": elements}, headers=headers["lead"]
    )
    assert response.status_code == 201, response.text
    return [int(e["id"]) for e in response.json()]


def next_item(client: TestClient, site_id: int, who: dict[str, str], **body: Any) -> dict[str, Any] | None:
    """POST queue/next: the lease JSON, or None on 204."""
    response = client.post(f"/api/sites/{site_id}/queue/next", json=body or None, headers=who)
    if response.status_code == 204:
        return None
    assert response.status_code == 200, response.text
    return dict(response.json())


def test_review_queue_order_filters_and_pages(client: TestClient, headers: Headers, site_id: int) -> None:
    mid, low, high = load_proposals(client, headers, site_id, [0.5, 0.1, 0.9])
    human = client.post(
        f"/api/sites/{site_id}/elements", json=crosswalk(60, 60), headers=headers["annotator"]
    )
    human_id = human.json()["id"]
    url = f"/api/sites/{site_id}/queue/review"
    page = client.get(url, headers=headers["lead"]).json()
    assert page["total"] == 4 and [e["id"] for e in page["items"]] == [low, mid, high, human_id]
    by_class = client.get(url, params={"class": "ped_crossing"}, headers=headers["lead"]).json()
    assert [e["id"] for e in by_class["items"]] == [human_id]
    by_author = client.get(url, params={"author": "annotator"}, headers=headers["admin"]).json()
    assert [e["id"] for e in by_author["items"]] == [human_id]
    near = client.get(url, params={"bbox": "0,0,12,7"}, headers=headers["lead"]).json()
    assert [e["id"] for e in near["items"]] == [mid]  # the first divider spans x 5..15, y 5..6
    second = client.get(url, params={"limit": 2, "offset": 2}, headers=headers["lead"]).json()
    assert second["total"] == 4 and [e["id"] for e in second["items"]] == [high, human_id]
    by_state = client.get(url, params={"state": "approved"}, headers=headers["lead"]).json()
    assert by_state == {"total": 0, "limit": 100, "offset": 0, "items": []}
    assert client.get(url, headers=headers["annotator"]).status_code == 403
    assert client.get(url).status_code == 401
    assert client.get(url, params={"bbox": "1,2"}, headers=headers["lead"]).status_code == 422
    assert client.get(url, params={"state": "bogus"}, headers=headers["lead"]).status_code == 422
    assert client.get("/api/sites/999/queue/review", headers=headers["lead"]).status_code == 404


def test_next_item_is_distinct_lowest_confidence_first(
    client: TestClient, headers: Headers, site_id: int
) -> None:
    mid, low, high = load_proposals(client, headers, site_id, [0.5, 0.1, 0.9])
    other = add_annotator(client, headers, "ann2")
    first = next_item(client, site_id, headers["annotator"])
    assert (
        first is not None
        and first["element_id"] == low
        and first["active"]
        and first["username"] == "annotator"
    )
    assert first["element"]["confidence"] == 0.1
    second = next_item(client, site_id, other)
    assert second is not None and second["element_id"] == mid
    third = next_item(client, site_id, headers["annotator"])
    assert third is not None and third["element_id"] == high
    assert next_item(client, site_id, other) is None  # everything is leased
    assert client.post("/api/sites/999/queue/next", headers=other).status_code == 404
    assert client.post(f"/api/sites/{site_id}/queue/next").status_code == 401
    bad = client.post(f"/api/sites/{site_id}/queue/next", json={"lease_s": 0}, headers=other)
    assert bad.status_code == 422


def test_release_and_renew(client: TestClient, headers: Headers, site_id: int) -> None:
    (only,) = load_proposals(client, headers, site_id, [0.3])
    other = add_annotator(client, headers, "ann2")
    lease = next_item(client, site_id, headers["annotator"], lease_s=60)
    assert lease is not None and lease["element_id"] == only
    lease_id = lease["id"]
    assert client.post(f"/api/leases/{lease_id}/renew", headers=other).status_code == 403
    assert client.post(f"/api/leases/{lease_id}/release", headers=other).status_code == 403
    renewed = client.post(
        f"/api/leases/{lease_id}/renew", json={"lease_s": 1200}, headers=headers["annotator"]
    )
    assert renewed.status_code == 200 and renewed.json()["expires_at"] > lease["expires_at"]
    released = client.post(f"/api/leases/{lease_id}/release", headers=headers["annotator"])
    assert released.status_code == 200 and not released.json()["active"] and released.json()["released_at"]
    again = client.post(f"/api/leases/{lease_id}/release", headers=headers["annotator"])
    assert again.status_code == 200  # idempotent
    assert client.post(f"/api/leases/{lease_id}/renew", headers=headers["annotator"]).status_code == 409
    taken = next_item(client, site_id, other)
    assert taken is not None and taken["element_id"] == only
    by_lead = client.post(f"/api/leases/{taken['id']}/release", headers=headers["lead"])
    assert by_lead.status_code == 200
    assert client.post("/api/leases/999/release", headers=headers["lead"]).status_code == 404
    assert client.post("/api/leases/999/renew", headers=headers["lead"]).status_code == 404


def test_expired_lease_frees_the_item(
    client: TestClient, headers: Headers, site_id: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    (only,) = load_proposals(client, headers, site_id, [0.3])
    other = add_annotator(client, headers, "ann2")
    lease = next_item(client, site_id, headers["annotator"])
    assert lease is not None and next_item(client, site_id, other) is None
    later = utc_now() + timedelta(seconds=DEFAULT_LEASE_S + 1)
    monkeypatch.setattr(leases, "clock", lambda: later)
    taken = next_item(client, site_id, other)
    assert taken is not None and taken["element_id"] == only and taken["username"] == "ann2"
    stale = client.post(f"/api/leases/{lease['id']}/renew", headers=headers["annotator"])
    assert stale.status_code == 409


def test_lint_findings_appear_in_the_queues(client: TestClient, headers: Headers, site_id: int) -> None:
    (clean,) = load_proposals(client, headers, site_id, [0.1])
    crossing = [
        {"class": "divider", "points": [[20, 40], [40, 40]], "source": "proposal", "confidence": c}
        for c in (0.5, 0.9)
    ]
    crossing[1]["points"] = [[30, 30], [30, 50]]
    response = client.post(
        f"/api/sites/{site_id}/elements/bulk", json={"elements": crossing}, headers=headers["lead"]
    )
    assert response.status_code == 201, response.text
    first, second = (int(e["id"]) for e in response.json())
    url = f"/api/sites/{site_id}/queue/review"
    flagged = client.get(url, params={"flagged": "true"}, headers=headers["lead"]).json()
    codes = {item["id"]: {f["code"] for f in item["lint"]} for item in flagged["items"]}
    assert "crossing_dividers" in codes[first] and "crossing_dividers" in codes[second]
    everything = client.get(url, headers=headers["lead"]).json()
    assert [item["id"] for item in everything["items"]] == [clean, first, second]
    lease = next_item(client, site_id, headers["annotator"])
    assert lease is not None and lease["element_id"] == first  # a lint error outranks lower confidence
    assert any(f["code"] == "crossing_dividers" for f in lease["lint"])
    assert [next_item(client, site_id, headers["annotator"])["element_id"] for _ in range(2)] == [
        second,
        clean,
    ]


def test_review_verdict_ends_the_lease(client: TestClient, headers: Headers, site_id: int) -> None:
    first, second = load_proposals(client, headers, site_id, [0.2, 0.4])
    lease = next_item(client, site_id, headers["annotator"])
    assert lease is not None and lease["element_id"] == first
    review = f"/api/sites/{site_id}/elements/{first}/review"
    stale = client.post(review, json={"state": "accepted", "version": 9}, headers=headers["annotator"])
    assert stale.status_code == 409
    held = client.get(f"/api/leases/{lease['id']}", headers=headers["annotator"]).json()
    assert held["active"]  # a refused review leaves the lease alone
    done = client.post(review, json={"state": "fixed", "version": 1}, headers=headers["annotator"])
    assert done.status_code == 200, done.text
    ended = client.get(f"/api/leases/{lease['id']}", headers=headers["annotator"]).json()
    assert not ended["active"] and ended["released_at"]
    following = next_item(client, site_id, headers["annotator"])
    assert following is not None and following["element_id"] == second


def test_returned_work_goes_first_to_its_annotator(
    client: TestClient, headers: Headers, site_id: int
) -> None:
    (first,) = load_proposals(client, headers, site_id, [0.2])
    other = add_annotator(client, headers, "ann2")
    lease = next_item(client, site_id, headers["annotator"])
    assert lease is not None and lease["element_id"] == first
    review = f"/api/sites/{site_id}/elements/{first}/review"
    accepted = client.post(review, json={"state": "accepted", "version": 1}, headers=headers["annotator"])
    assert accepted.status_code == 200, accepted.text
    client.post(f"/api/leases/{lease['id']}/release", headers=headers["annotator"])
    returned = client.post(review, json={"state": "returned", "version": 2}, headers=headers["lead"])
    assert returned.status_code == 200, returned.text
    load_proposals(client, headers, site_id, [0.01])  # a lower-confidence proposal arrives meanwhile
    mine = next_item(client, site_id, headers["annotator"])
    assert mine is not None and mine["element_id"] == first and mine["element"]["state"] == "returned"
    theirs = next_item(client, site_id, other)
    assert theirs is not None and theirs["element_id"] != first
    assert next_item(client, site_id, other) is None  # returned work of others is never handed out


def test_concurrent_annotators_never_share_an_item(
    client: TestClient, headers: Headers, site_id: int
) -> None:
    n_workers, per_worker = 11, 3
    ids = load_proposals(client, headers, site_id, [0.01 * i for i in range(n_workers * per_worker - 2)])
    workers = [add_annotator(client, headers, f"w{i}") for i in range(n_workers)]
    barrier = threading.Barrier(n_workers)
    got: list[list[int]] = [[] for _ in workers]
    errors: list[str] = []

    def work(index: int) -> None:
        own = TestClient(client.app)  # a separate client: separate requests, sessions and connections
        barrier.wait()
        for _ in range(per_worker):
            response = own.post(f"/api/sites/{site_id}/queue/next", headers=workers[index])
            if response.status_code == 200:
                got[index].append(int(response.json()["element_id"]))
            elif response.status_code != 204:
                errors.append(response.text)

    threads = [threading.Thread(target=work, args=(i,)) for i in range(n_workers)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert not errors
    leased = [element_id for items in got for element_id in items]
    assert (
        len(leased) == len(set(leased)) == len(ids)
    )  # every item once, two workers got nothing the 3rd time
    assert set(leased) == set(ids)
