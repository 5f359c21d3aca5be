"""The camera panel in headless Chromium, on the tiny synthetic site registered with its reconstruction (images,
SfM poses, lane masks) and its ground-truth map: the drawn projection lies on the images' lane masks (read from
the canvas pixels), a divider moved 1 m leaves them and its SRE rises, the live projection follows a vertex drag
at >= 30 frames per second, a site without images shows the notice, and image paths cannot escape the data set.
"""

import statistics
from typing import Any

import pytest
from playwright.sync_api import Page, expect

from cama_studio.pipeline import PipelineResult
from tests.conftest import GeneratedSite
from tests.frontend.camera_browser_helpers import (
    CameraSite,
    page_fetch,
    register_camera_site,
    view_on_mask,
)
from tests.frontend.editor_browser_helpers import (
    SeededServer,
    centre_on,
    drag,
    log_in,
    open_editor,
    page_xy,
)

pytestmark = pytest.mark.slow  # the tiny site's whole path runs once per session (shared with other tests)

RES_M = 0.05
"""Map resolution of the drag tests: 20 px per metre."""
FRAME_BUDGET_MS = 1000 / 30
"""30 frames per second."""
SOLID_ELEMENT = "gt-0022"
"""A ground-truth kerb (solid: every drawn pixel can lie on its mask, where a dashed line's gaps cannot)."""
MIN_DRAWN_PX = 20
"""A view counts in the on-mask share when it draws at least this many pixels of the element."""
FREE_LINE = ((-36.0, 0.0), (-22.0, 0.0))
"""A stretch of the ground-truth divider gt-0005 (not loaded), where tests draw their own divider."""


@pytest.fixture(scope="module")
def camera_site(seeded: SeededServer, tiny_site: GeneratedSite, whole_path: PipelineResult) -> CameraSite:
    """The tiny site with its reconstruction and ground-truth map, on the shared server."""
    return register_camera_site(seeded, tiny_site.result.out_dir, whole_path.workspace, "Tiny site cameras")


def element(seeded: SeededServer, site_id: int, element_id: int) -> dict[str, Any]:
    """An element of a site as the API has it now."""
    with seeded.client() as client:
        response = client.get(f"/api/sites/{site_id}/elements/{element_id}", headers=seeded.headers["lead"])
    response.raise_for_status()
    return dict(response.json())


def open_panel(page: Page, seeded: SeededServer, site_id: int, element_id: int) -> list[dict[str, Any]]:
    """Open the editor on the element (selected), open the camera panel with ⇧C and wait until every view
    shows its image with the server's projection; what the panel shows, per view."""
    open_editor(page, seeded, query=f"?element={element_id}", site_id=site_id)
    page.wait_for_selector(f".selected-element[data-id='{element_id}']")
    page.keyboard.press("Shift+C")
    expect(page.locator("#camera-button")).to_have_attribute("aria-pressed", "true")
    return wait_server_projection(page)


def wait_server_projection(page: Page, version: int | None = None) -> list[dict[str, Any]]:
    """Wait until the panel shows at least two views, each with its image and the server's projection (of
    element `version` when given); the panel's description of them."""
    page.wait_for_function(
        """(version) => {
            const views = [...document.querySelectorAll('#camera-grid .camera-view')];
            return views.length >= 2 && views.every((v) => v.dataset.loaded === 'image'
                && v.dataset.projected === 'server' && (version === null || v.dataset.version === String(version)));
        }""",
        arg=version,
        timeout=60_000,
    )
    views: list[dict[str, Any]] = page.evaluate("() => window.camaEditor.cameras().views")
    return views


def on_mask(page: Page, site_id: int, views: list[dict[str, Any]]) -> list[float]:
    """Per view that draws a fair part of the element (at least MIN_DRAWN_PX pixels), the share of its drawn
    pixels that lie on the image's lane mask."""
    shares = []
    for index, view in enumerate(views):
        drawn, share = view_on_mask(page, site_id, index, view["token"])
        if drawn >= MIN_DRAWN_PX:
            shares.append(share)
    return shares


def figures(page: Page, element_id: int, version: int) -> str:
    """The review panel's reprojection SRE of this element version (empty: unmatched), once it arrived."""
    ready = f"[data-id='{element_id}'][data-version='{version}'][data-state='ready']"
    line = page.locator(f"#selection-info .reprojection{ready}")
    expect(line).to_have_count(1, timeout=60_000)
    return line.get_attribute("data-sre") or ""


def test_selected_element_is_drawn_on_its_lane_mask(
    page: Page, seeded: SeededServer, camera_site: CameraSite
) -> None:
    element_id = camera_site.element_ids[SOLID_ELEMENT]
    views = open_panel(page, seeded, camera_site.site_id, element_id)
    assert 2 <= len(views) <= 6 and all(view["pieces"] for view in views), views
    shares = on_mask(page, camera_site.site_id, views)
    assert len(shares) >= 2 and min(shares) >= 0.8, f"share of the drawn element on the lane masks: {shares}"
    version = element(seeded, camera_site.site_id, element_id)["version"]
    sre = figures(page, element_id, version)
    assert sre and float(sre) < 8.0, f"SRE {sre!r} px of a ground-truth element"
    expect(page.locator("#camera-figures .reprojection")).to_contain_text("SRE")


def test_divider_moved_one_metre_leaves_its_mask(
    page: Page, seeded: SeededServer, camera_site: CameraSite
) -> None:
    (x0, y), (x1, _) = FREE_LINE
    with seeded.client() as client:
        body = {"class": "divider", "points": [[x0, y], [x1, y]]}
        created = client.post(
            f"/api/sites/{camera_site.site_id}/elements", json=body, headers=seeded.headers["ann"]
        )
    created.raise_for_status()
    divider = created.json()
    views = open_panel(page, seeded, camera_site.site_id, divider["id"])
    before = on_mask(page, camera_site.site_id, views)
    sre_before = figures(page, divider["id"], divider["version"])
    assert len(before) >= 2 and min(before) >= 0.8 and sre_before, (before, sre_before)
    centre_on(page, (x0 + x1) / 2, y, RES_M)
    for x in (x0, x1):
        drag(page, page_xy(page, x, y), page_xy(page, x, y + 1.0))
    version = divider["version"] + 2
    views = wait_server_projection(page, version)
    saved = element(seeded, camera_site.site_id, divider["id"])
    assert saved["version"] == version and all(abs(p[1] - (y + 1.0)) < 0.1 for p in saved["points"]), saved
    after = on_mask(page, camera_site.site_id, views)
    sre_after = figures(page, divider["id"], version)
    assert len(after) >= 2 and max(after) <= min(before) - 0.3, (
        f"on the lane masks: {before} before, {after} after"
    )
    assert sre_after and float(sre_after) > float(sre_before) + 1.0, f"SRE {sre_before} -> {sre_after} px"


def test_projection_follows_a_vertex_drag_at_30_fps(
    page: Page, seeded: SeededServer, camera_site: CameraSite
) -> None:
    (x0, y), (x1, _) = FREE_LINE
    with seeded.client() as client:
        body = {"class": "divider", "points": [[x0, y - 1.5], [x1, y - 1.5]]}
        created = client.post(
            f"/api/sites/{camera_site.site_id}/elements", json=body, headers=seeded.headers["ann"]
        )
    created.raise_for_status()
    divider = created.json()
    before = open_panel(page, seeded, camera_site.site_id, divider["id"])
    centre_on(page, (x0 + x1) / 2, y, RES_M)
    page.evaluate(
        """() => {
            window.frameTimes = [];
            window.recordFrames = true;
            const tick = (t) => { window.frameTimes.push(t); if (window.recordFrames) requestAnimationFrame(tick); };
            requestAnimationFrame(tick);
        }"""
    )
    live_before = page.evaluate("() => window.camaEditor.cameras().liveFrames")
    start = page_xy(page, x1, y - 1.5)
    page.mouse.move(start[0] - 3, start[1] - 3)
    page.mouse.move(*start)
    page.mouse.down()
    for i in range(1, 61):  # 3 m sideways over about a second of frames
        page.mouse.move(start[0], start[1] - i)
        page.wait_for_timeout(16)
    during: dict[str, Any] = page.evaluate("() => window.camaEditor.cameras()")
    page.mouse.up()
    times: list[float] = page.evaluate("() => { window.recordFrames = false; return window.frameTimes; }")
    intervals = [b - a for a, b in zip(times, times[1:], strict=False)]
    assert len(intervals) >= 20, f"only {len(intervals)} frames during the drag"
    median = statistics.median(intervals)
    assert median <= FRAME_BUDGET_MS, (
        f"median frame time {median:.1f} ms during the drag (> {FRAME_BUDGET_MS:.1f})"
    )
    assert during["liveFrames"] - live_before >= 10, during["liveFrames"]
    draw_ms = statistics.median(during["liveDrawMs"])
    assert draw_ms <= FRAME_BUDGET_MS / 2, f"a live redraw of every view takes {draw_ms:.1f} ms (median)"
    assert all(v["projected"] == "live" for v in during["views"]), during["views"]
    moved = [v for v, b in zip(during["views"], before, strict=True) if v["pieces"] != b["pieces"]]
    assert moved, "the live projection did not change while the vertex moved"
    wait_server_projection(page, divider["version"] + 1)


def test_point_views_and_stepping_along_the_element(
    page: Page, seeded: SeededServer, camera_site: CameraSite
) -> None:
    element_id = camera_site.element_ids[SOLID_ELEMENT]
    first = open_panel(page, seeded, camera_site.site_id, element_id)
    page.keyboard.press("}")
    expect(page.locator("#camera-status")).to_contain_text("along it")
    stepped = wait_server_projection(page)
    assert [v["token"] for v in stepped] != [v["token"] for v in first]
    page.locator("#camera-grid .camera-view").first.click()
    expect(page.locator("#camera-enlarged canvas")).to_have_count(1)
    page.keyboard.press("Escape")
    expect(page.locator("#camera-enlarged")).to_have_count(0)
    (x0, y), _ = FREE_LINE
    centre_on(page, x0, y, RES_M)
    page.mouse.move(*page_xy(page, x0, y))
    page.keyboard.press("Shift+V")
    page.wait_for_function(
        """() => {
            const views = [...document.querySelectorAll('#camera-grid .camera-view')];
            return views.length >= 2 && views.every((v) => v.dataset.loaded === 'image' && v.dataset.marker === 'shown');
        }""",
        timeout=30_000,
    )


def test_lead_queue_of_worst_reprojection(page: Page, seeded: SeededServer, camera_site: CameraSite) -> None:
    log_in(page, seeded.base_url, "lead", f"#/site/{camera_site.site_id}/lead")
    rows = page.locator("#reprojection-table tr.queue-row")
    expect(rows.first).to_be_visible(timeout=60_000)
    ranked: list[str] = rows.evaluate_all("rows => rows.map(r => r.dataset.sre)")
    numbers = [float(v) for v in ranked if v]
    assert ranked[: len(ranked) - len(numbers)] == [""] * (len(ranked) - len(numbers)), (
        ranked
    )  # unmatched first
    assert numbers == sorted(numbers, reverse=True), ranked
    worst = rows.first.get_attribute("data-id")
    rows.first.click()
    expect(page.locator(f".selected-element[data-id='{worst}']")).to_have_count(1)


def test_site_without_images_shows_the_notice(page: Page, seeded: SeededServer) -> None:
    with seeded.client() as client:
        response = client.get(f"/api/sites/{seeded.site_id}/cameras", headers=seeded.headers["ann"])
    response.raise_for_status()
    status = response.json()
    assert not status["available"] and status["notice"], status
    open_editor(page, seeded)
    page.click("#camera-button")
    expect(page.locator("#camera-panel")).to_be_visible()
    expect(page.locator("#camera-status")).to_have_text(status["notice"])
    expect(page.locator("#camera-status")).to_have_attribute("data-notice", "true")
    expect(page.locator("#camera-grid canvas")).to_have_count(0)
    page.keyboard.press("Shift+C")
    expect(page.locator("#camera-panel")).to_be_hidden()


ESCAPES = [
    "..%2F..%2F..%2Fetc%2Fpasswd",
    "%2Fetc%2Fpasswd",
    "samples%2FCAM_FRONT%2Fx.jpg",
    "a.b",
    "x" * 129,
]


def test_image_paths_cannot_escape(
    page: Page, seeded: SeededServer, camera_site: CameraSite, tiny_site: GeneratedSite
) -> None:
    open_editor(page, seeded, site_id=camera_site.site_id)
    base = f"/api/sites/{camera_site.site_id}/images"
    secret = str(tiny_site.result.out_dir)
    for token in ESCAPES:
        for suffix in ("", "/lane-mask", "/camera"):
            status, body = page_fetch(page, f"{base}/{token}{suffix}")
            assert status in (404, 422), f"{token}{suffix}: HTTP {status}"
            assert secret not in body.decode("utf-8", "replace") and b"Traceback" not in body, body[:300]
    status, _ = page_fetch(page, f"{base}/not-a-token-of-this-site")
    assert status == 404
