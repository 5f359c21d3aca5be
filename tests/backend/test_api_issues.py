"""Review issues through the HTTP API: pin, list and filter, comment thread, resolve and reopen, roles, 404s."""

from collections.abc import Callable
from typing import Any

from fastapi.testclient import TestClient

Headers = dict[str, dict[str, str]]
MakeElement = Callable[..., dict[str, Any]]


def test_issue_lifecycle(
    client: TestClient, headers: Headers, site_id: int, make_element: MakeElement
) -> None:
    element = make_element()
    url = f"/api/sites/{site_id}/issues"
    on_point = {"reason": "missing_element", "comment": "a divider is missing here", "point": [40.0, 40.0]}
    created = client.post(url, json=on_point, headers=headers["lead"])
    assert created.status_code == 201, created.text
    issue = created.json()
    assert issue["status"] == "open" and issue["point"] == [40.0, 40.0] and issue["element_id"] is None
    assert [(c["kind"], c["username"]) for c in issue["comments"]] == [("open", "lead")]
    on_element = {"reason": "wrong_geometry", "comment": "end is off", "element_id": element["id"]}
    second = client.post(url, json=on_element, headers=headers["admin"]).json()
    assert second["element_id"] == element["id"] and second["point"] is None

    reply = client.post(
        f"/api/issues/{issue['id']}/comments", json={"body": "added it"}, headers=headers["annotator"]
    )
    assert reply.status_code == 201 and reply.json()["comments"][-1]["body"] == "added it"
    resolved = client.post(
        f"/api/issues/{issue['id']}/resolve", json={"comment": "ok"}, headers=headers["lead"]
    )
    assert resolved.status_code == 200 and resolved.json()["status"] == "resolved"
    assert client.post(f"/api/issues/{issue['id']}/resolve", headers=headers["lead"]).status_code == 409
    open_only = client.get(url, params={"status": "open"}, headers=headers["annotator"]).json()
    assert [i["id"] for i in open_only] == [second["id"]]
    by_element = client.get(url, params={"element_id": element["id"]}, headers=headers["lead"]).json()
    assert [i["id"] for i in by_element] == [second["id"]]
    by_reason = client.get(url, params={"reason": "missing_element"}, headers=headers["lead"]).json()
    assert [i["id"] for i in by_reason] == [issue["id"]]
    reopened = client.post(f"/api/issues/{issue['id']}/reopen", headers=headers["lead"])
    assert reopened.status_code == 200 and reopened.json()["status"] == "open"
    assert client.post(f"/api/issues/{issue['id']}/reopen", headers=headers["lead"]).status_code == 409
    thread = client.get(f"/api/issues/{issue['id']}", headers=headers["annotator"]).json()["comments"]
    assert [c["kind"] for c in thread] == ["open", "comment", "resolve", "reopen"]
    assert thread[2]["body"] == "ok" and thread[2]["username"] == "lead"
    assert len(client.get(url, params={"limit": 1}, headers=headers["lead"]).json()) == 1


def test_issue_roles_and_bad_input(
    client: TestClient, headers: Headers, site_id: int, make_element: MakeElement
) -> None:
    url = f"/api/sites/{site_id}/issues"
    body = {"reason": "other", "comment": "look", "point": [10.0, 10.0]}
    assert client.post(url, json=body, headers=headers["annotator"]).status_code == 403
    assert client.post(url, json=body).status_code == 401
    issue_id = client.post(url, json=body, headers=headers["lead"]).json()["id"]
    assert client.post(f"/api/issues/{issue_id}/resolve", headers=headers["annotator"]).status_code == 403
    assert client.post(f"/api/issues/{issue_id}/reopen", headers=headers["annotator"]).status_code == 403
    unpinned = {"reason": "other", "comment": "where?"}
    assert client.post(url, json=unpinned, headers=headers["lead"]).status_code == 422
    far = {**body, "point": [5000.0, 5000.0]}
    assert client.post(url, json=far, headers=headers["lead"]).status_code == 422
    bad_reason = {**body, "reason": "ugly"}
    assert client.post(url, json=bad_reason, headers=headers["lead"]).status_code == 422
    nan = '{"reason": "other", "comment": "x", "point": [NaN, 1]}'
    response = client.post(url, content=nan, headers={**headers["lead"], "Content-Type": "application/json"})
    assert response.status_code == 422
    empty = client.post(f"/api/issues/{issue_id}/comments", json={"body": ""}, headers=headers["lead"])
    assert empty.status_code == 422
    missing_element = {**body, "element_id": 999}
    assert client.post(url, json=missing_element, headers=headers["lead"]).status_code == 404
    assert client.post("/api/sites/999/issues", json=body, headers=headers["lead"]).status_code == 404
    assert client.get("/api/sites/999/issues", headers=headers["lead"]).status_code == 404
    assert client.get("/api/issues/999", headers=headers["lead"]).status_code == 404
    comment = {"body": "hi"}
    assert client.post("/api/issues/999/comments", json=comment, headers=headers["lead"]).status_code == 404
    assert client.post("/api/issues/999/resolve", headers=headers["lead"]).status_code == 404
    assert client.post("/api/issues/999/reopen", headers=headers["lead"]).status_code == 404
