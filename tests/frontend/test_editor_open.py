"""Log in, open a site, see the raster tiles and the elements, the legend, the help overlay and the cursor readout."""

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from playwright.sync_api import Page, expect

from tests.frontend.editor_browser_helpers import (
    PROPOSALS,
    PROPOSED_BY,
    SITE_ORIGIN_XY,
    SeededServer,
    centre_on,
    georeference,
    log_in,
    open_editor,
    page_xy,
    screenshot,
    select_at,
)

pytestmark = pytest.mark.slow  # each test is a few seconds; the shared server and browser start once


def test_login_rejects_a_wrong_password(page: Page, seeded: SeededServer) -> None:
    page.goto(f"{seeded.base_url}/")
    page.fill("#username", "ann")
    page.fill("#password", "not the password")
    page.click("#login-submit")
    expect(page.locator(".form-error")).to_contain_text("wrong username or password")


def test_log_out_revokes_the_token_on_the_server(page: Page, seeded: SeededServer) -> None:
    log_in(page, seeded.base_url, "ann")
    token = page.evaluate("sessionStorage.getItem('cama.token')")
    with page.expect_response(lambda response: response.url.endswith("/api/auth/logout")) as logout:
        page.click("#logout")
    assert logout.value.status == 204
    expect(page.locator("#username")).to_be_visible()
    with seeded.client() as client:
        assert client.get("/api/auth/me", headers={"Authorization": f"Bearer {token}"}).status_code == 401


def test_open_site_loads_tiles_and_elements(page: Page, seeded: SeededServer) -> None:
    tiles: list[int] = []
    page.on("response", lambda r: tiles.append(r.status) if "/tiles/" in r.url else None)
    log_in(page, seeded.base_url, "ann")
    page.click(f".site-card[data-site-id='{seeded.site_id}']")
    page.wait_for_function("window.camaEditor && window.camaEditor.firstRenderMs !== null")
    with seeded.client() as client:
        live = client.get(f"/api/sites/{seeded.site_id}/elements", headers=seeded.headers["ann"]).json()
    assert len(live) >= len(PROPOSALS)
    assert page.evaluate("window.camaEditor.elementCount()") == len(live)
    expect(page.locator("#element-count")).to_have_text(f"{len(live)} elements")
    page.wait_for_function(
        "() => [...document.querySelectorAll('#map canvas')].length > 0 && performance.getEntriesByType('resource')"
        ".filter(e => e.name.includes('/tiles/photometric/')).length >= 2"
    )
    assert tiles and all(status == 200 for status in tiles), tiles
    page.click(".sidebar-tab[data-tab='Layers']")
    page.check("#layers-panel input[data-layer='elevation']")
    expect(page.locator(".layer-row[data-layer='elevation'] .colorbar")).to_be_visible()
    expect(page.locator(".layer-row[data-layer='elevation'] .colorbar-labels")).to_contain_text("m")
    page.wait_for_function(
        "() => performance.getEntriesByType('resource').some(e => e.name.includes('/tiles/elevation/'))"
    )
    page.uncheck("#layers-panel input[data-layer='elevation']")
    page.click(".sidebar-tab[data-tab='Review']")
    centre_on(page, 30.0, 40.0, 0.06)
    page.mouse.move(*page_xy(page, 30.0, 40.0))
    expect(page.locator("#cursor-xy")).to_contain_text("x 30.0")
    expect(page.locator("#cursor-elevation")).to_contain_text(" m")
    low = seeded.element(2)
    centre_on(page, 62.0, 42.0, 0.09)
    (ax, ay), (bx, by) = low["points"][:2]
    select_at(page, seeded, low["id"], (ax + bx) / 2, (ay + by) / 2)
    expect(page.locator(".selected-element .sel-meta").first).to_contain_text("(low)")
    expect(page.locator(".selected-element .proposed-by")).to_have_text(PROPOSED_BY)
    page.mouse.move(*page_xy(page, 75.0, 50.0))
    page.wait_for_timeout(400)
    screenshot(page, "editor")


def map_colours(page: Page, points: list[tuple[float, float]]) -> list[tuple[int, int, int]]:
    """RGB of the rendered map at site points (from a screenshot, so every layer is composed)."""
    image = cv2.imdecode(np.frombuffer(page.screenshot(), np.uint8), cv2.IMREAD_COLOR)
    assert image is not None, "the screenshot did not decode"
    colours = []
    for x, y in points:
        px, py = page_xy(page, x, y)
        b, g, r = image[round(py), round(px)]
        colours.append((int(r), int(g), int(b)))
    return colours


def test_tiles_line_up_with_site_coordinates(page: Page, seeded: SeededServer) -> None:
    """Painted marks land where the site coordinates say, also on the cut right-edge tiles."""
    open_editor(page, seeded)
    page.click(".sidebar-tab[data-tab='Layers']")
    page.uncheck("#layers-panel label.layer-row input")
    for centre_x in (30.0, 108.0):
        centre_on(page, centre_x, 40.0, 0.1)
        page.wait_for_timeout(600)
        dash, gap, asphalt, grass = map_colours(
            page,
            [(centre_x + 1.5, 40.0), (centre_x + 4.5, 40.0), (centre_x, 30.0), (centre_x, 62.0)],
        )
        assert min(dash) > 200, f"centre line dash at x={centre_x + 1.5}: {dash}"
        assert max(gap) < 130 and max(asphalt) < 130, (gap, asphalt)
        assert grass[1] > grass[0] + 15, f"grass north of the road: {grass}"


def test_help_overlay_lists_shortcuts(page: Page, seeded: SeededServer) -> None:
    open_editor(page, seeded)
    page.keyboard.press("?")
    overlay = page.locator("#help-overlay")
    expect(overlay).to_be_visible()
    for label in ("Undo", "Redo", "Accept (unchanged)", "Relabel as boundary", "Next item of my queue"):
        expect(overlay).to_contain_text(label)
    screenshot(page, "help")
    page.keyboard.press("Escape")
    expect(overlay).to_have_count(0)


def test_a_site_with_unreadable_rasters_still_opens_for_vector_work(
    page: Page, seeded: SeededServer, tmp_path: Path
) -> None:
    rasters = tmp_path / "broken"
    rasters.mkdir()
    (rasters / "semantic.png").write_bytes(b"not a png")
    (rasters / "georeference.json").write_text(json.dumps(georeference()))
    body = {
        "name": "broken rasters",
        "site_origin_xy": list(SITE_ORIGIN_XY),
        "georeference": georeference(),
        "raster_dir": str(rasters),
    }
    with seeded.client() as client:
        response = client.post("/api/sites", json=body, headers=seeded.headers["lead"])
        assert response.status_code == 201, response.text
        site_id = response.json()["id"]
        element = {"class": "divider", "points": [[10.0, 10.0], [20.0, 10.0]]}
        path = f"/api/sites/{site_id}/elements"
        assert client.post(path, json=element, headers=seeded.headers["ann"]).status_code == 201
    log_in(page, seeded.base_url, "ann", f"#/site/{site_id}")
    page.wait_for_function("window.camaEditor && window.camaEditor.firstRenderMs !== null")
    expect(page.locator(".toast.error")).to_contain_text("Raster layers unavailable")
    assert page.evaluate("window.camaEditor.elementCount()") == 1
    page.click(".sidebar-tab[data-tab='Layers']")
    expect(page.locator("#layers-panel")).to_contain_text("no raster layers")
