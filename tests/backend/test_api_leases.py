"""Leases are enforced: while another user's lease holds an element, an annotator's update, delete, review or
restore of it is refused with 409 naming the holder and the expiry; the holder, leads and admins may write."""

from collections.abc import Callable
from datetime import timedelta
from typing import Any

import pytest
from fastapi.testclient import TestClient

from app.backend.clock import utc_now
from app.backend.crud import leases
from app.backend.schemas_review import DEFAULT_LEASE_S
from tests.backend.backend_helpers import PASSWORD, divider, login

Headers = dict[str, dict[str, str]]
Write = Callable[[TestClient, str, int, dict[str, str]], Any]

WRITES: dict[str, Write] = {
    "patch geometry": lambda c, url, v, who: c.patch(
        url, json={"version": v, "points": [[30, 30], [40, 30]]}, headers=who
    ),
    "patch class": lambda c, url, v, who: c.patch(url, json={"version": v, "class": "boundary"}, headers=who),
    "delete": lambda c, url, v, who: c.delete(url, params={"version": v}, headers=who),
    "reject": lambda c, url, v, who: c.post(
        f"{url}/review", json={"state": "rejected", "version": v}, headers=who
    ),
    "restore": lambda c, url, v, who: c.post(f"{url}/history/1/restore", json={"version": v}, headers=who),
}
"""Every write route that changes one existing element."""


@pytest.fixture
def other(client: TestClient, headers: Headers) -> dict[str, str]:
    """A second annotator's auth headers."""
    body = {"username": "ann2", "password": PASSWORD, "role": "annotator"}
    assert client.post("/api/users", json=body, headers=headers["admin"]).status_code == 201
    return login(client, "ann2")


@pytest.fixture
def leased(client: TestClient, headers: Headers, site_id: int) -> dict[str, Any]:
    """One proposal, leased to `annotator` through the work queue: the lease JSON."""
    proposal = divider(10, 10, source="proposal", confidence=0.3)
    loaded = client.post(
        f"/api/sites/{site_id}/elements/bulk", json={"elements": [proposal]}, headers=headers["lead"]
    )
    assert loaded.status_code == 201, loaded.text
    lease = client.post(f"/api/sites/{site_id}/queue/next", headers=headers["annotator"])
    assert lease.status_code == 200, lease.text
    return dict(lease.json())


def element_url(site_id: int, lease: dict[str, Any]) -> str:
    return f"/api/sites/{site_id}/elements/{lease['element_id']}"


@pytest.mark.parametrize("write", sorted(WRITES))
def test_another_annotators_write_is_refused_naming_holder_and_expiry(
    client: TestClient,
    headers: Headers,
    site_id: int,
    leased: dict[str, Any],
    other: dict[str, str],
    write: str,
) -> None:
    url = element_url(site_id, leased)
    refused = WRITES[write](client, url, 1, other)
    assert refused.status_code == 409, refused.text
    detail = refused.json()["detail"]
    assert "'annotator'" in detail and leased["expires_at"][:19] in detail  # to the second
    assert client.get(url, headers=other).json()["version"] == 1
    assert len(client.get(f"{url}/history", headers=other).json()) == 1
    assert client.get(f"/api/leases/{leased['id']}", headers=headers["annotator"]).json()["active"]


@pytest.mark.parametrize("write", sorted(WRITES))
def test_the_holder_writes(
    client: TestClient, headers: Headers, site_id: int, leased: dict[str, Any], write: str
) -> None:
    done = WRITES[write](client, element_url(site_id, leased), 1, headers["annotator"])
    assert done.status_code == 200, done.text


@pytest.mark.parametrize("role", ["lead", "admin"])
@pytest.mark.parametrize("write", ["patch geometry", "reject"])
def test_leads_and_admins_override(
    client: TestClient, headers: Headers, site_id: int, leased: dict[str, Any], role: str, write: str
) -> None:
    done = WRITES[write](client, element_url(site_id, leased), 1, headers[role])
    assert done.status_code == 200, done.text
    history = client.get(f"{element_url(site_id, leased)}/history", headers=headers["lead"]).json()
    assert history[-1]["username"] == ("root" if role == "admin" else "lead")


def test_an_expired_or_released_lease_holds_nothing(
    client: TestClient,
    headers: Headers,
    site_id: int,
    leased: dict[str, Any],
    other: dict[str, str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    url = element_url(site_id, leased)
    later = utc_now() + timedelta(seconds=DEFAULT_LEASE_S + 1)
    monkeypatch.setattr(leases, "clock", lambda: later)
    assert WRITES["patch class"](client, url, 1, other).status_code == 200  # expired, not yet reclaimed
    monkeypatch.undo()
    assert WRITES["patch geometry"](client, url, 2, other).status_code == 409  # still unexpired by the clock
    released = client.post(f"/api/leases/{leased['id']}/release", headers=headers["annotator"])
    assert released.status_code == 200
    assert WRITES["reject"](client, url, 2, other).status_code == 200


def test_region_leases_hold_each_element(
    client: TestClient, headers: Headers, site_id: int, other: dict[str, str]
) -> None:
    proposals = [divider(10 + 3 * i, 10, source="proposal", confidence=0.1 * (i + 1)) for i in range(3)]
    loaded = client.post(
        f"/api/sites/{site_id}/elements/bulk", json={"elements": proposals}, headers=headers["lead"]
    )
    assert loaded.status_code == 201, loaded.text
    region = client.post(f"/api/sites/{site_id}/queue/next-region", headers=headers["annotator"])
    assert region.status_code == 200, region.text
    members = region.json()["leases"]
    assert len(members) == 3
    for lease in members:
        refused = WRITES["patch geometry"](client, element_url(site_id, lease), 1, other)
        assert refused.status_code == 409 and "'annotator'" in refused.json()["detail"]
