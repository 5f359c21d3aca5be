"""The top bar's "3D review" link: it points at the review `cama demo` serves (CAMA_REVIEW_URL), carries the
selected element, and opens the viser review focused on that element, with the site's vectors in its scene."""

import re
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any
from urllib.parse import parse_qs, urlsplit

import numpy as np
import pytest
import viser
from playwright.sync_api import Page, expect

from app.viewer.content import load_surface, local_frame_of, road_mesh
from app.viewer.review import show_vectors
from app.viewer.scene import ReviewScene
from app.viewer.sources import ApiVectorSource
from tests.backend_system.system_helpers import PASSWORD
from tests.frontend.editor_browser_helpers import (
    SeededServer,
    centre_on,
    open_editor,
    polyline,
    screenshot,
    select_at,
)

LINK_PROPOSALS: list[dict[str, Any]] = [
    {"class": "divider", "points": polyline(10, 30, 40, 5), "confidence": 0.4},
    {"class": "boundary", "points": polyline(2, 118, 20.2, 12), "confidence": 0.7},
]


def _link_site(seeded: SeededServer, name: str) -> tuple[int, int]:
    """A site of its own and the id of its divider (at x 10..30 m, y 40 m)."""
    site_id = seeded.add_site(name, LINK_PROPOSALS)
    with seeded.client() as client:
        response = client.get(f"/api/sites/{site_id}/elements", headers=seeded.headers["lead"])
    divider = next(e for e in response.json() if e["class"] == "divider")
    return site_id, int(divider["id"])


def _socket_of(href: str) -> str:
    """The websocket URL a review link hands to viser's page."""
    return parse_qs(urlsplit(href).query)["websocket"][0]


def _select_divider(page: Page, seeded: SeededServer, element_id: int) -> None:
    centre_on(page, 20.0, 40.0, 0.05)
    select_at(page, seeded, element_id, 17.5, 40.0)


def test_the_top_bar_links_to_the_review_and_carries_the_selection(
    page: Page, seeded: SeededServer, review_url: str
) -> None:
    site_id, divider = _link_site(seeded, "Review link")
    open_editor(page, seeded, "lead", site_id=site_id)
    link = page.locator("#review-link")
    expect(link).to_have_attribute("href", review_url)
    expect(link).to_have_attribute("target", "_blank")
    _select_divider(page, seeded, divider)
    expect(link).to_have_attribute("href", re.compile(r"\?websocket="))
    href = link.get_attribute("href") or ""
    assert href.startswith(f"{review_url}?")
    assert _socket_of(href) == f"ws://{review_url.removeprefix('http://')}?element={divider}"
    page.keyboard.press("Escape")
    expect(link).to_have_attribute("href", review_url)
    page.click("a.tab:text('Lead')")
    expect(page.locator("#review-link")).to_have_attribute("href", review_url)


@pytest.fixture
def review(seeded: SeededServer, review_url: str, tmp_path: Path) -> Iterator[tuple[ReviewScene, int]]:
    """The 3D review of a fresh site on the seeded rasters, following the seeded server, served where the
    editor's link points; with the site's id."""
    assert seeded.raster_dir is not None
    site_id, _ = _link_site(seeded, "Review in 3D")
    port = int(urlsplit(review_url).port or 0)
    server = viser.ViserServer(host="127.0.0.1", port=port, verbose=False)
    source = ApiVectorSource(seeded.base_url, site_id, "lead", PASSWORD)
    try:
        assert server.get_port() == port, "the review's port was taken"
        surface = load_surface(seeded.raster_dir, reconstructed=True)
        frame = local_frame_of(surface)
        scene = ReviewScene(server, frame, surface)
        scene.add_mesh(road_mesh(tmp_path, "no-mesh", surface, frame, max_faces=5_000))
        yield show_vectors(scene, source), site_id
    finally:
        source.close()
        server.stop()


def _camera_looks_at(server: viser.ViserServer, target: np.ndarray, timeout_s: float = 15.0) -> bool:
    """Whether a connected browser's camera comes to look at `target` (view frame) in time."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        for client in server.get_clients().values():
            try:
                if np.allclose(client.camera.look_at, target, atol=0.05):
                    return True
            except AssertionError:  # viser's guard: this browser has not reported its camera yet
                continue
        time.sleep(0.2)
    return False


@pytest.mark.slow
def test_the_link_opens_the_review_on_the_element(
    page: Page, seeded: SeededServer, review: tuple[ReviewScene, int]
) -> None:
    scene, site_id = review
    with seeded.client() as client:
        elements = client.get(f"/api/sites/{site_id}/elements", headers=seeded.headers["lead"]).json()
    assert all(scene.element_centre(str(e["id"])) is not None for e in elements), "every vector is drawn"
    divider = next(int(e["id"]) for e in elements if e["class"] == "divider")
    open_editor(page, seeded, "lead", site_id=site_id)
    _select_divider(page, seeded, divider)
    with page.context.expect_page() as opened:
        page.click("#review-link")
    viewer = opened.value
    expect(viewer.get_by_text(f"Element {divider}", exact=True)).to_be_visible(timeout=40_000)
    expect(viewer.get_by_text("state: proposed")).to_be_visible()
    expect(viewer.get_by_text("Road mesh")).to_be_visible()
    assert scene.selected == str(divider)
    centre = scene.element_centre(str(divider))
    assert centre is not None and _camera_looks_at(scene.server, centre), "the browser's camera looks at it"
    screenshot(viewer, "review_focused")
