"""Concurrency: 20 clients editing overlapping elements; every conflict is detected and no update is lost."""

import random
import threading
from collections import Counter
from dataclasses import dataclass, field

import httpx
import pytest

from tests.backend_system.system_helpers import ServerProcess, create_elements, divider_points, history

N_CLIENTS = 20
N_ELEMENTS = 4
EDITS_PER_CLIENT = 15


@dataclass
class Tally:
    """Outcomes of all clients' PATCHes, guarded by `lock`."""

    lock: threading.Lock = field(default_factory=threading.Lock)
    acked: dict[tuple[int, int], list[list[float]]] = field(default_factory=dict)
    """(element id, version the edit produced) -> points it wrote."""
    duplicates: list[tuple[int, int]] = field(default_factory=list)
    """(element id, version) acknowledged twice: a conflict that went undetected."""
    status: Counter[int] = field(default_factory=Counter)
    bad_conflicts: list[str] = field(default_factory=list)
    """409 bodies that do not carry the element as stored now."""


def edit_loop(
    base_url: str, headers: dict[str, str], site_id: int, ids: list[int], client_no: int, tally: Tally
) -> None:
    """Read a random element, then PATCH it with the version read; record 200s and 409s."""
    rng = random.Random(client_no)
    with httpx.Client(base_url=base_url, headers=headers, timeout=20.0) as client:
        for edit_no in range(EDITS_PER_CLIENT):
            element_id = rng.choice(ids)
            url = f"/api/sites/{site_id}/elements/{element_id}"
            read = client.get(url)
            read.raise_for_status()
            points = divider_points(1.0 + client_no * 3.0, 1.0 + edit_no * 4.0)  # unique per (client, edit)
            response = client.patch(url, json={"version": read.json()["version"], "points": points})
            with tally.lock:
                tally.status[response.status_code] += 1
                if response.status_code == 200:
                    key = (element_id, int(response.json()["version"]))
                    if key in tally.acked:
                        tally.duplicates.append(key)
                    tally.acked[key] = points
                elif (
                    response.status_code == 409
                    and (response.json().get("current") or {}).get("id") != element_id
                ):
                    tally.bad_conflicts.append(response.text)


@pytest.mark.slow
def test_twenty_clients_overlapping_edits_no_lost_update(
    server: ServerProcess, api: httpx.Client, admin_headers: dict[str, str], site_id: int
) -> None:
    ids = create_elements(api, admin_headers, site_id, N_ELEMENTS)
    tally = Tally()
    workers = [
        threading.Thread(target=edit_loop, args=(server.base_url, admin_headers, site_id, ids, n, tally))
        for n in range(N_CLIENTS)
    ]
    for worker in workers:
        worker.start()
    for worker in workers:
        worker.join(timeout=60)
    assert not any(worker.is_alive() for worker in workers)

    assert set(tally.status) <= {200, 409}, tally.status
    assert tally.status[200] + tally.status[409] == N_CLIENTS * EDITS_PER_CLIENT
    assert tally.status[409] > 0, "no conflict at all: the test did not exercise concurrent edits"
    assert tally.bad_conflicts == []
    assert tally.duplicates == [], "two edits acknowledged as the same version"
    for element_id in ids:
        successes = sorted(version for (eid, version) in tally.acked if eid == element_id)
        stored = api.get(f"/api/sites/{site_id}/elements/{element_id}", headers=admin_headers).json()
        assert stored["version"] == 1 + len(successes)
        assert successes == list(range(2, stored["version"] + 1))
        if successes:
            assert stored["points"] == tally.acked[(element_id, successes[-1])]
        log = history(api, admin_headers, site_id, element_id)
        assert [entry["version"] for entry in log] == list(range(1, stored["version"] + 1))
        assert [entry["action"] for entry in log[1:]] == ["update"] * len(successes)
        for entry in log[1:]:
            assert entry["after"]["points"] == tally.acked[(element_id, entry["version"])]
