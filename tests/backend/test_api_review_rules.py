"""Review rules hold for every write of an element: an annotator cannot change approved work by editing,
deleting, reviewing or restoring it (a lead can), and returned work stays the annotators' to fix."""

from collections.abc import Callable
from typing import Any

import pytest
from fastapi.testclient import TestClient

from tests.backend.backend_helpers import divider

Headers = dict[str, dict[str, str]]
MakeElement = Callable[..., dict[str, Any]]
Write = Callable[[TestClient, str, int, dict[str, str]], Any]


def review(client: TestClient, url: str, state: str, version: int, who: dict[str, str]) -> Any:
    """Post a review transition."""
    return client.post(f"{url}/review", json={"state": state, "version": version}, headers=who)


@pytest.fixture
def approved_url(client: TestClient, headers: Headers, site_id: int, make_element: MakeElement) -> str:
    """An element the annotator accepted and the lead approved (version 3)."""
    url = f"/api/sites/{site_id}/elements/{make_element()['id']}"
    assert review(client, url, "accepted", 1, headers["annotator"]).status_code == 200
    approved = review(client, url, "approved", 2, headers["lead"])
    assert approved.status_code == 200 and approved.json()["version"] == 3, approved.text
    return url


WRITES: dict[str, Write] = {
    "patch geometry": lambda c, url, v, who: c.patch(
        url, json={"version": v, "points": [[30, 30], [40, 30]]}, headers=who
    ),
    "patch class": lambda c, url, v, who: c.patch(url, json={"version": v, "class": "boundary"}, headers=who),
    "patch confidence": lambda c, url, v, who: c.patch(
        url, json={"version": v, "confidence": 0.2}, headers=who
    ),
    "delete": lambda c, url, v, who: c.delete(url, params={"version": v}, headers=who),
    "restore": lambda c, url, v, who: c.post(f"{url}/history/1/restore", json={"version": v}, headers=who),
}
"""Every write route that changes one existing element, except review transitions (tested by state)."""


@pytest.mark.parametrize("write", sorted(WRITES))
def test_annotator_cannot_change_approved_work(
    client: TestClient, headers: Headers, approved_url: str, write: str
) -> None:
    refused = WRITES[write](client, approved_url, 3, headers["annotator"])
    assert refused.status_code == 403, refused.text
    detail = refused.json()["detail"]
    assert "approved" in detail and "lead" in detail
    element = client.get(approved_url, headers=headers["lead"]).json()
    assert (element["state"], element["version"], element["deleted"]) == ("approved", 3, False)
    assert len(client.get(f"{approved_url}/history", headers=headers["lead"]).json()) == 3


@pytest.mark.parametrize("state", ["accepted", "fixed", "rejected", "returned", "approved"])
def test_annotator_cannot_move_approved_work(
    client: TestClient, headers: Headers, approved_url: str, state: str
) -> None:
    refused = review(client, approved_url, state, 3, headers["annotator"])
    assert refused.status_code in (403, 409), refused.text
    assert client.get(approved_url, headers=headers["lead"]).json()["version"] == 3


@pytest.mark.parametrize("write", ["patch geometry", "patch class", "delete"])
def test_a_lead_may_change_approved_work(
    client: TestClient, headers: Headers, approved_url: str, write: str
) -> None:
    changed = WRITES[write](client, approved_url, 3, headers["lead"])
    assert changed.status_code == 200, changed.text
    assert changed.json()["state"] == "approved" and changed.json()["author"] == "lead"


def test_returned_work_is_fixed_by_annotators_then_locked_again(
    client: TestClient, headers: Headers, approved_url: str
) -> None:
    returned = review(client, approved_url, "returned", 3, headers["lead"])
    assert returned.status_code == 200, returned.text
    fixed_geometry = WRITES["patch geometry"](client, approved_url, 4, headers["annotator"])
    assert fixed_geometry.status_code == 200, fixed_geometry.text
    assert fixed_geometry.json()["state"] == "returned"  # an edit keeps the state: the verdict is a review
    assert review(client, approved_url, "approved", 5, headers["annotator"]).status_code == 403
    assert review(client, approved_url, "fixed", 5, headers["annotator"]).json()["state"] == "fixed"
    assert review(client, approved_url, "approved", 6, headers["lead"]).json()["state"] == "approved"
    assert WRITES["patch class"](client, approved_url, 7, headers["annotator"]).status_code == 403


def test_an_annotator_may_delete_returned_work(
    client: TestClient, headers: Headers, approved_url: str
) -> None:
    assert review(client, approved_url, "returned", 3, headers["lead"]).status_code == 200
    deleted = WRITES["delete"](client, approved_url, 4, headers["annotator"])
    assert deleted.status_code == 200 and deleted.json()["deleted"], deleted.text  # as returned -> rejected


def test_create_and_bulk_cannot_overwrite_an_element(
    client: TestClient, headers: Headers, site_id: int, approved_url: str
) -> None:
    element_id = int(approved_url.rsplit("/", 1)[1])
    base = f"/api/sites/{site_id}/elements"
    over = divider(30, 30, id=element_id, state="proposed")
    assert client.post(base, json=over, headers=headers["annotator"]).status_code == 422
    bulk = {"elements": [{**over, "source": "proposal", "confidence": 0.5}]}
    assert client.post(f"{base}/bulk", json=bulk, headers=headers["lead"]).status_code == 422
    assert client.get(approved_url, headers=headers["lead"]).json()["version"] == 3
