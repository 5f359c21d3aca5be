"""Region work items through HTTP: a grid cell's proposals leased together, disjoint between annotators."""

from typing import Any

from fastapi.testclient import TestClient

from tests.backend.backend_helpers import PASSWORD, divider, login

Headers = dict[str, dict[str, str]]


def next_region(client: TestClient, site_id: int, who: dict[str, str], **body: Any) -> dict[str, Any] | None:
    response = client.post(f"/api/sites/{site_id}/queue/next-region", json=body or None, headers=who)
    if response.status_code == 204:
        return None
    assert response.status_code == 200, response.text
    return dict(response.json())


def test_regions_are_leased_whole_and_never_shared(
    client: TestClient, headers: Headers, site_id: int
) -> None:
    # cells of 50 m: (0, 0) holds three proposals, (50, 0) two, (0, 50) one
    places = [
        (5.0, 5.0, 0.5),
        (20.0, 30.0, 0.2),
        (30.0, 10.0, 0.9),
        (60.0, 10.0, 0.1),
        (70.0, 20.0, 0.6),
        (10.0, 60.0, 0.7),
    ]
    bodies = [divider(x, y, source="proposal", confidence=c) for x, y, c in places]
    created = client.post(
        f"/api/sites/{site_id}/elements/bulk", json={"elements": bodies}, headers=headers["lead"]
    )
    ids = [e["id"] for e in created.json()]
    response = client.post(
        "/api/users",
        json={"username": "ann2", "password": PASSWORD, "role": "annotator"},
        headers=headers["admin"],
    )
    assert response.status_code == 201, response.text
    other = login(client, "ann2")
    first = next_region(client, site_id, headers["annotator"])
    assert first is not None and first["bbox"] == [
        50.0,
        0.0,
        100.0,
        50.0,
    ]  # holds the lowest confidence (0.1)
    assert [lease["element_id"] for lease in first["leases"]] == [ids[3], ids[4]]
    assert all(lease["active"] and lease["username"] == "annotator" for lease in first["leases"])
    second = next_region(client, site_id, other)
    assert second is not None and second["bbox"] == [0.0, 0.0, 50.0, 50.0]
    assert [lease["element_id"] for lease in second["leases"]] == [ids[1], ids[0], ids[2]]
    single = client.post(f"/api/sites/{site_id}/queue/next", headers=headers["lead"]).json()
    assert single["element_id"] == ids[5]  # element work items skip leased regions too
    assert next_region(client, site_id, headers["lead"]) is None
    lease = second["leases"][0]
    released = client.post(f"/api/leases/{lease['id']}/release", headers=other)
    assert released.status_code == 200
    again = next_region(client, site_id, headers["lead"], cell_m=25.0)
    assert again is not None and [item["element_id"] for item in again["leases"]] == [ids[1]]
    assert again["bbox"] == [25.0, 25.0, 50.0, 50.0]  # centre (25, 30.5)


def test_region_request_is_validated(client: TestClient, headers: Headers, site_id: int) -> None:
    url = f"/api/sites/{site_id}/queue/next-region"
    assert client.post(url, json={"cell_m": 1.0}, headers=headers["annotator"]).status_code == 422
    assert client.post(url, json={"size": 50}, headers=headers["annotator"]).status_code == 422
    assert client.post(url, headers=headers["annotator"]).status_code == 204
    assert client.post("/api/sites/999/queue/next-region", headers=headers["annotator"]).status_code == 404
    assert client.post(url).status_code == 401
