"""Region work items in the editor: ⇧N leases a grid cell's proposals, the map frames the cell with its outline,
the panel lists them with the lease's time left, reviews tick them off, and leaving gives the leases back."""

import re
from typing import Any

import pytest
from playwright.sync_api import Page, expect

from tests.frontend.editor_browser_helpers import SeededServer, log_in, polyline, screenshot

pytestmark = pytest.mark.slow  # a few seconds each; the shared server and browser start once

# The default 50 m cells: the three first ones share the cell x [0, 50), y [0, 50); the last one lies beside it.
REGION_PROPOSALS: list[dict[str, Any]] = [
    {"class": "divider", "points": polyline(10, 30, 40, 5), "confidence": 0.1},
    {"class": "boundary", "points": polyline(5, 45, 20.2, 6), "confidence": 0.5},
    {
        "class": "ped_crossing",
        "points": [[40, 30], [48, 30], [48, 45], [40, 45], [40, 30]],
        "confidence": 0.9,
    },
    {"class": "divider", "points": polyline(60, 100, 40, 5), "confidence": 0.3},
]


def _site_elements(seeded: SeededServer, site_id: int) -> list[dict[str, Any]]:
    with seeded.client() as client:
        response = client.get(f"/api/sites/{site_id}/elements", headers=seeded.headers["lead"])
    response.raise_for_status()
    return sorted(response.json(), key=lambda e: e["id"])


def _next_for_bob(seeded: SeededServer, site_id: int) -> dict[str, Any] | None:
    """What the other annotator's `queue/next` hands out (and gives it straight back)."""
    with seeded.client() as client:
        response = client.post(f"/api/sites/{site_id}/queue/next", headers=seeded.headers["bob"])
        if response.status_code == 204:
            return None
        lease = response.json()
        client.post(f"/api/leases/{lease['id']}/release", headers=seeded.headers["bob"]).raise_for_status()
    return dict(lease["element"])


def _open(page: Page, seeded: SeededServer, site_id: int) -> None:
    log_in(page, seeded.base_url, "ann", f"#/site/{site_id}")
    page.wait_for_function("window.camaEditor && window.camaEditor.firstRenderMs !== null")


def test_next_region_frames_lists_and_completes_the_cell(page: Page, seeded: SeededServer) -> None:
    site_id = seeded.add_site("Region work", REGION_PROPOSALS)
    first, second, third, beside = (e["id"] for e in _site_elements(seeded, site_id))
    _open(page, seeded, site_id)
    page.keyboard.press("Shift+N")
    panel = page.locator("#region-panel")
    expect(panel).to_be_visible()
    items = panel.locator(".region-item")
    expect(items).to_have_count(3)
    assert [int(i.get_attribute("data-id") or 0) for i in items.all()] == [first, second, third]
    expect(page.locator("#region-status")).to_contain_text("0/3 done")
    expect(page.locator("#region-lease")).to_have_text(re.compile(r"lease (10:00|9:[0-5]\d) left"))
    assert page.evaluate("window.camaEditor.regionOutlines()") == [[0, 0, 50, 50]]
    box = page.locator("#map").bounding_box()
    assert box is not None
    page.wait_for_function(  # the map flies to the cell (a 250 ms animation): wait for it to arrive
        """([w, h]) => { const [px, py] = window.camaEditor.pixelOf(25, 25);
                         return Math.abs(px - w / 2) < 30 && Math.abs(py - h / 2) < 30; }""",
        arg=[box["width"], box["height"]],
        timeout=5000,
    )
    assert (_next_for_bob(seeded, site_id) or {}).get("id") == beside, (
        "the cell's proposals are leased to ann"
    )
    expect(page.locator(f".selected-element[data-id='{first}']")).to_be_visible()
    screenshot(page, "region")

    page.keyboard.press("a")
    expect(items.nth(0)).to_have_class("region-item done")
    expect(page.locator("#region-status")).to_contain_text("1/3 done")
    page.keyboard.press(".")
    expect(page.locator(f".selected-element[data-id='{second}']")).to_be_visible()
    page.keyboard.press("x")
    expect(page.locator("#region-status")).to_contain_text("2/3 done")
    page.keyboard.press(".")
    expect(page.locator(f".selected-element[data-id='{third}']")).to_be_visible()
    page.keyboard.press("a")
    expect(page.locator("#region-status")).to_contain_text("Region complete (3/3)")
    states = {e["id"]: e["state"] for e in _site_elements(seeded, site_id)}
    assert [states[i] for i in (first, second, third, beside)] == [
        "accepted",
        "rejected",
        "accepted",
        "proposed",
    ]


def test_leaving_the_editor_gives_the_region_back(page: Page, seeded: SeededServer) -> None:
    site_id = seeded.add_site("Region release", REGION_PROPOSALS)
    ids = [e["id"] for e in _site_elements(seeded, site_id)]
    _open(page, seeded, site_id)
    page.click("#next-region")
    expect(page.locator("#region-panel .region-item")).to_have_count(3)
    assert (_next_for_bob(seeded, site_id) or {}).get("id") == ids[3]
    page.keyboard.press("n")  # a single item instead: the region goes back, its outline with it
    expect(page.locator("#region-panel")).to_be_hidden()
    assert page.evaluate("window.camaEditor.regionOutlines()") == []
    expect(page.locator("#queue-info")).to_contain_text("leased until")
    held = int(page.locator(".selected-element").get_attribute("data-id") or 0)
    assert held == ids[0], "the lowest-confidence proposal is the single item now"
    page.evaluate("window.location.hash = '#/sites'")
    page.wait_for_selector(".site-card")
    assert (_next_for_bob(seeded, site_id) or {}).get("id") == ids[0], "leaving released the item"
