"""The element changes cursor: everything once, then exactly what was created, changed or deleted; an idle poll
carries no element; a change committed late with a smaller edit-log id is not skipped (PostgreSQL); the logs
leave successful polls out."""

import logging
from collections.abc import Callable
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient

from app.backend.models import EditLog
from app.backend.poll_log import QuietChangePolls
from tests.backend.backend_helpers import crosswalk, divider, register_site

Headers = dict[str, dict[str, str]]
MakeElement = Callable[..., dict[str, Any]]


def _changes(client: TestClient, headers: Headers, site_id: int, since: int) -> dict[str, Any]:
    response = client.get(
        f"/api/sites/{site_id}/elements/changes", params={"since": since}, headers=headers["lead"]
    )
    assert response.status_code == 200, response.text
    return dict(response.json())


def test_changes_since_a_cursor_are_exactly_the_edits(
    client: TestClient, headers: Headers, site_id: int, make_element: MakeElement, raster_dir: Path
) -> None:
    moved, reviewed, removed = make_element(divider(10, 10)), make_element(divider(30, 30)), make_element()
    everything = _changes(client, headers, site_id, 0)
    assert [e["id"] for e in everything["elements"]] == [moved["id"], reviewed["id"], removed["id"]]
    assert everything["deleted"] == []
    cursor = everything["cursor"]
    idle = client.get(
        f"/api/sites/{site_id}/elements/changes", params={"since": cursor}, headers=headers["lead"]
    )
    assert idle.json() == {"cursor": cursor, "elements": [], "deleted": []}
    assert len(idle.content) < 64  # no element data

    base = f"/api/sites/{site_id}/elements"
    lead = headers["lead"]
    assert client.patch(
        f"{base}/{moved['id']}", json={"version": 1, "points": [[12, 10], [20, 10]]}, headers=lead
    ).is_success
    assert client.post(
        f"{base}/{reviewed['id']}/review", json={"state": "accepted", "version": 1}, headers=lead
    ).is_success
    assert client.delete(f"{base}/{removed['id']}", params={"version": 1}, headers=lead).is_success
    added = make_element(crosswalk())
    born_and_gone = make_element(divider(40, 40))
    assert client.delete(f"{base}/{born_and_gone['id']}", params={"version": 1}, headers=lead).is_success
    other_site = register_site(client, lead, raster_dir, "s2")  # its edits are not this site's changes
    assert client.post(f"/api/sites/{other_site}/elements", json=divider(), headers=lead).is_success

    changes = _changes(client, headers, site_id, cursor)
    by_id = {e["id"]: e for e in changes["elements"]}
    assert sorted(by_id) == [moved["id"], reviewed["id"], added["id"]]
    assert by_id[moved["id"]]["points"] == [[12.0, 10.0], [20.0, 10.0]]
    assert by_id[reviewed["id"]]["state"] == "accepted"
    assert changes["deleted"] == [removed["id"]]  # the element made and deleted since was never seen
    assert changes["cursor"] > cursor
    assert _changes(client, headers, site_id, changes["cursor"])["elements"] == []

    restored = client.post(f"{base}/{removed['id']}/history/1/restore", json={"version": 2}, headers=lead)
    assert restored.is_success, restored.text
    again = _changes(client, headers, site_id, changes["cursor"])
    assert [e["id"] for e in again["elements"]] == [removed["id"]] and again["deleted"] == []


def test_changes_need_a_login_a_known_site_and_a_cursor_of_this_log(
    client: TestClient, headers: Headers, site_id: int, make_element: MakeElement
) -> None:
    make_element()
    path = f"/api/sites/{site_id}/elements/changes"
    assert client.get(path).status_code == 401
    assert client.get("/api/sites/999/elements/changes", headers=headers["lead"]).status_code == 404
    assert client.get(path, params={"since": -1}, headers=headers["lead"]).status_code == 422
    newest = _changes(client, headers, site_id, 0)["cursor"]
    for beyond in (newest + 1, 2**63 - 1):
        assert _changes(client, headers, site_id, beyond) == {"cursor": 0, "elements": [], "deleted": []}


@pytest.mark.parametrize("database_url", ["postgresql"], indirect=True)
def test_a_change_committed_late_with_a_smaller_id_is_not_skipped(
    client: TestClient, headers: Headers, site_id: int, make_element: MakeElement
) -> None:
    """PostgreSQL hands out ids before commit: the poll must not move its cursor past an uncommitted one."""
    early = make_element()
    cursor = _changes(client, headers, site_id, 0)["cursor"]
    with client.app.state.sessionmaker() as late:  # type: ignore[attr-defined]
        entry = EditLog(
            element_id=early["id"],
            version=1,
            username="late",
            at=datetime.now(UTC),
            action="update",
            before=None,
            after={},
        )
        late.add(entry)
        late.flush()  # id taken, not committed
        later = make_element(divider(50, 50))  # committed with a larger id
        waiting = _changes(client, headers, site_id, cursor)  # must not move past the uncommitted id
        late.commit()
    changes = _changes(client, headers, site_id, waiting["cursor"])
    assert {e["id"] for e in waiting["elements"] + changes["elements"]} == {early["id"], later["id"]}


@pytest.mark.parametrize(
    ("args", "kept"),
    [
        (("GET", "http://127.0.0.1:8000/api/sites/1/elements/changes?since=7", "HTTP/1.1", 200, "OK"), False),
        (("GET", "http://127.0.0.1:8000/api/sites/1/elements/changes?since=7", "HTTP/1.1", 401, "x"), True),
        (("GET", "http://127.0.0.1:8000/api/sites/1/elements?limit=10", "HTTP/1.1", 200, "OK"), True),
        (("127.0.0.1:5000", "GET", "/api/sites/1/elements/changes?since=7", "1.1", 200), False),
        (("127.0.0.1:5000", "PATCH", "/api/sites/1/elements/4", "1.1", 200), True),
    ],
)
def test_successful_change_polls_are_left_out_of_the_request_logs(
    args: tuple[object, ...], kept: bool
) -> None:
    """The first three as httpx logs a request, the others as uvicorn's access log does."""
    record = logging.LogRecord("httpx", logging.INFO, __file__, 1, "%s %s %s %s %s", args, None)
    assert QuietChangePolls().filter(record) is kept
