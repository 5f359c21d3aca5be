"""Conflicts between two clients, the annotator queue's "next", findings and issue threads (text, never HTML)."""

import pytest
from playwright.sync_api import Page, expect

from tests.frontend.editor_browser_helpers import (
    SeededServer,
    centre_on,
    drag,
    open_editor,
    page_xy,
    screenshot,
    select_at,
)

pytestmark = pytest.mark.slow  # each test is a few seconds; the shared server and browser start once

INJECTION = '<img src=x onerror="window.__xss=1"><script>window.__xss=2</script>'


def test_conflicting_edit_keeps_both_sides(page: Page, seeded: SeededServer) -> None:
    element = seeded.create({"class": "divider", "points": [[4.0, 74.0], [9.0, 74.0], [14.0, 74.0]]})
    open_editor(page, seeded)
    centre_on(page, 9.0, 74.0, 0.05)
    select_at(page, seeded, element["id"], 6.5, 74.0)
    theirs = [[4.0, 75.0], [9.0, 74.0], [14.0, 74.0]]
    with seeded.client() as bob:
        response = bob.patch(
            f"/api/sites/{seeded.site_id}/elements/{element['id']}",
            json={"version": element["version"], "points": theirs},
            headers=seeded.headers["bob"],
        )
    assert response.status_code == 200, response.text
    drag(page, page_xy(page, 14.0, 74.0), page_xy(page, 14.0, 72.5))
    banner = page.locator("#conflict-banner")
    expect(banner).to_be_visible()
    expect(banner).to_contain_text(f"Conflict on element #{element['id']}")
    expect(banner.locator(".author")).to_have_text("bob")
    expect(page.locator("#save-state")).to_have_attribute("data-state", "conflict")
    assert seeded.element(element["id"])["points"] == theirs, "the other client's save must stand"
    screenshot(page, "conflict")
    banner.locator(".merge-both").click()
    merged = seeded.wait_element(element["id"], lambda e: e["version"] == 3)
    assert merged["points"][0] == [4.0, 75.0], "their moved vertex is kept"
    assert abs(merged["points"][2][1] - 72.5) < 0.15, "my moved vertex is kept"
    expect(banner).to_be_hidden()


def test_use_mine_after_a_conflict(page: Page, seeded: SeededServer) -> None:
    element = seeded.create({"class": "divider", "points": [[20.0, 74.0], [25.0, 74.0], [30.0, 74.0]]})
    open_editor(page, seeded)
    centre_on(page, 25.0, 74.0, 0.05)
    select_at(page, seeded, element["id"], 22.5, 74.0)
    with seeded.client() as bob:
        body = {"version": 1, "class": "boundary"}
        path = f"/api/sites/{seeded.site_id}/elements/{element['id']}"
        assert bob.patch(path, json=body, headers=seeded.headers["bob"]).status_code == 200
    drag(page, page_xy(page, 25.0, 74.0), page_xy(page, 25.0, 75.5))
    banner = page.locator("#conflict-banner")
    expect(banner.locator(".use-mine")).to_be_visible()
    expect(banner.locator(".merge-both")).to_have_count(0)
    banner.locator(".use-mine").click()
    mine = seeded.wait_element(element["id"], lambda e: e["version"] == 3)
    assert abs(mine["points"][1][1] - 75.5) < 0.15
    with seeded.client() as client:
        history = client.get(f"{path}/history", headers=seeded.headers["lead"]).json()
    assert [entry["username"] for entry in history] == ["ann", "bob", "ann"], "bob's version stays in the log"


def test_next_leases_and_centres_the_lowest_confidence_proposal(page: Page, seeded: SeededServer) -> None:
    open_editor(page, seeded, "bob")
    page.keyboard.press("n")
    selected = page.locator(".selected-element")
    expect(selected).to_have_count(1)
    expect(page.locator("#queue-info")).to_contain_text("leased until")
    element = seeded.element(int(selected.get_attribute("data-id") or 0))
    assert element["state"] == "proposed" and element["confidence"] is not None
    with seeded.client() as client:
        queue = client.get(
            f"/api/sites/{seeded.site_id}/queue/review",
            params={"state": "proposed"},
            headers=seeded.headers["lead"],
        ).json()
    proposals = [e["confidence"] for e in queue["items"] if e["confidence"] is not None]
    assert element["confidence"] == min(proposals)
    page.wait_for_timeout(400)
    centre = page.evaluate("window.camaEditor.pixelOf(0, 0)")
    box = page.locator("#map").bounding_box()
    assert box is not None
    xs = [p[0] for p in element["points"]]
    ys = [p[1] for p in element["points"]]
    cx, cy = page_xy(page, (min(xs) + max(xs)) / 2, (min(ys) + max(ys)) / 2)
    assert abs(cx - (box["x"] + box["width"] / 2)) < 5 and abs(cy - (box["y"] + box["height"] / 2)) < 5, (
        centre
    )


def test_findings_and_issue_threads_render_text(page: Page, seeded: SeededServer) -> None:
    element = seeded.create({"class": "divider", "points": [[40.0, 76.0], [45.0, 76.0]]})
    with seeded.client() as client:
        body = {"reason": "wrong_geometry", "comment": INJECTION, "element_id": element["id"]}
        response = client.post(
            f"/api/sites/{seeded.site_id}/issues", json=body, headers=seeded.headers["lead"]
        )
    assert response.status_code == 201, response.text
    issue_id = response.json()["id"]
    open_editor(page, seeded)
    page.click(".sidebar-tab[data-tab='Findings']")
    item = page.locator(f".finding[data-key='issue-{issue_id}']")
    expect(item).to_contain_text(INJECTION)
    expect(page.locator(".finding.lint").first).to_be_visible()
    item.click()
    thread = page.locator("#issue-thread")
    expect(thread.locator(".comment-body").first).to_have_text(INJECTION)
    expect(page.locator("#selection-count")).to_have_text("1 selected")
    page.fill("#reply-text", f"fixed it {INJECTION}")
    page.click("#send-reply")
    expect(thread.locator(".comment-body")).to_have_count(2)
    expect(thread.locator(".comment-body").nth(1)).to_have_text(f"fixed it {INJECTION}")
    assert thread.locator("img, script").count() == 0
    assert page.evaluate("window.__xss") is None
    screenshot(page, "findings")
    first = page.locator(".finding.active").get_attribute("data-key")
    page.keyboard.press("]")
    expect(page.locator(".finding.active")).not_to_have_attribute("data-key", first or "")
