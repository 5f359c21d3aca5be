"""The lint cache patched after edits equals a full lint of the site, edit after edit."""

from typing import Any

import numpy as np
from fastapi.testclient import TestClient

from app.backend.crud.quality import LintCache, lint_site

Headers = dict[str, dict[str, str]]


def _random_divider(rng: np.random.Generator) -> dict[str, Any]:
    """A short divider somewhere in the 100 m test site, often near others (crossings, spacing, ends)."""
    x0, y0 = rng.uniform(5.0, 80.0), rng.uniform(5.0, 90.0)
    angle = rng.choice([0.0, 0.0, np.pi / 2, rng.uniform(0, np.pi)])
    length = rng.uniform(4.0, 15.0)
    points = [[x0 + t * np.cos(angle), y0 + t * np.sin(angle)] for t in np.linspace(0.0, length, 3)]
    return {"class": "divider", "points": [[round(x, 3), round(y, 3)] for x, y in points]}


def _findings(report: Any) -> list[tuple]:
    return sorted(
        (f.code, tuple(sorted(f.element_ids)), round(f.location_xy[0], 6), round(f.location_xy[1], 6))
        for f in report.findings
    )


def test_patched_lint_equals_a_full_lint_after_every_edit(
    client: TestClient, headers: Headers, site_id: int
) -> None:
    rng = np.random.default_rng(7)
    url = f"/api/sites/{site_id}/elements"
    bodies = [_random_divider(rng) for _ in range(60)]
    created = client.post(f"{url}/bulk", json={"elements": bodies}, headers=headers["lead"]).json()
    live = {element["id"]: element for element in created}
    sessions = client.app.state.sessionmaker  # type: ignore[attr-defined]
    cache = LintCache()
    with sessions() as session:
        assert lint_site(session=session, site_id=site_id, cache=cache).findings
    for step in range(25):
        action = step % 3
        if action == 0:  # move one
            element = live[int(rng.choice(sorted(live)))]
            points = [[x + rng.uniform(-3, 3), y + rng.uniform(-3, 3)] for x, y in element["points"]]
            body = {"version": element["version"], "points": points}
            response = client.patch(f"{url}/{element['id']}", json=body, headers=headers["lead"])
        elif action == 1:  # delete one
            element = live.pop(int(rng.choice(sorted(live))))
            response = client.delete(
                f"{url}/{element['id']}?version={element['version']}", headers=headers["lead"]
            )
        else:  # draw one
            response = client.post(url, json=_random_divider(rng), headers=headers["lead"])
        assert response.status_code in (200, 201), response.text
        if action != 1:
            live[response.json()["id"]] = response.json()
        with sessions() as session:
            patched = lint_site(session=session, site_id=site_id, cache=cache)
            full = lint_site(session=session, site_id=site_id, cache=LintCache())
        assert patched.element_count == full.element_count == len(live)
        assert _findings(patched) == _findings(full), f"step {step}"
