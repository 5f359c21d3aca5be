"""Log in, open a site, see the raster tiles and the elements, the legend, the help overlay and the cursor readout."""

from editor_browser_helpers import (
    PROPOSALS,
    SeededServer,
    centre_on,
    log_in,
    open_editor,
    page_xy,
    screenshot,
)
from playwright.sync_api import Page, expect


def test_login_rejects_a_wrong_password(page: Page, seeded: SeededServer) -> None:
    page.goto(f"{seeded.base_url}/")
    page.fill("#username", "ann")
    page.fill("#password", "not the password")
    page.click("#login-submit")
    expect(page.locator(".form-error")).to_contain_text("wrong username or password")


def test_open_site_loads_tiles_and_elements(page: Page, seeded: SeededServer) -> None:
    tiles: list[int] = []
    page.on("response", lambda r: tiles.append(r.status) if "/tiles/" in r.url else None)
    log_in(page, seeded.base_url, "ann")
    page.click(f".site-card[data-site-id='{seeded.site_id}']")
    page.wait_for_function("window.camaEditor && window.camaEditor.firstRenderMs !== null")
    assert page.evaluate("window.camaEditor.elementCount()") == len(PROPOSALS)
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
    page.wait_for_timeout(300)
    screenshot(page, "editor")


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
