"""Helpers of the browser tests and the editor bench: a painted raster site, a seeded server, Chromium, map clicks.

The site is 120 m x 80 m at 0.1 m/px: an east-west road (y 20..60 m) with a dashed centre line, curbs, a
crosswalk at x 40..48 m, a gentle elevation slope; proposals lie on the painted markings.
"""

import json
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import httpx
import numpy as np
import pytest
from playwright.sync_api import Browser, Page, Playwright

from tests.backend_system.system_helpers import PASSWORD, ServerProcess, login

CHROMIUM_PATH = "/usr/bin/chromium"
CHROMIUM_ARGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]
SITE_ORIGIN_XY = (5000.0, 7000.0)
RESOLUTION_M = 0.1
SITE_SIZE_M = (120.0, 80.0)
USERS = {"ann": "annotator", "bob": "annotator", "lead": "lead"}
SCREENSHOT_DIR = Path(__file__).resolve().parents[2] / "test-output" / "editor"


def georeference() -> dict[str, Any]:
    """Pixel (0, 0) centre at the site's top-left corner (global metres), rows growing with -y."""
    width, height = (round(size / RESOLUTION_M) for size in SITE_SIZE_M)
    origin = (SITE_ORIGIN_XY[0] + RESOLUTION_M / 2, SITE_ORIGIN_XY[1] + SITE_SIZE_M[1] - RESOLUTION_M / 2)
    return {"origin_xy": list(origin), "resolution": RESOLUTION_M, "width": width, "height": height}


def _site_xy_grid() -> tuple[np.ndarray, np.ndarray]:
    """Site metres of every raster pixel centre (x by column, y by row, rows growing with -y)."""
    geo = georeference()
    cols = (np.arange(geo["width"]) + 0.5) * RESOLUTION_M
    rows = SITE_SIZE_M[1] - (np.arange(geo["height"]) + 0.5) * RESOLUTION_M
    return np.meshgrid(cols, rows)


def write_rasters(folder: Path) -> Path:
    """Paint the four BEV layers and the georeference of the test site into `folder`."""
    folder.mkdir(parents=True, exist_ok=True)
    x, y = _site_xy_grid()
    rng = np.random.default_rng(7)
    road = (y > 20) & (y < 60)
    curb = road & ((y < 20.4) | (y > 59.6))
    centre = road & (np.abs(y - 40) < 0.08) & ((x % 6) < 3)
    crosswalk = road & (x > 40) & (x < 48) & ((y % 1.2) < 0.6) & ~curb
    marking = centre | crosswalk
    semantic = np.zeros(x.shape, np.uint8)
    semantic[road] = 1
    semantic[curb] = 2
    semantic[centre] = 3
    semantic[crosswalk] = 4
    noise = rng.normal(0, 9, x.shape)
    grass = np.stack([60 + noise, 95 + noise, 70 + noise], axis=-1)
    asphalt = np.stack([78 + noise, 80 + noise, 84 + noise], axis=-1)
    photo = np.where(road[..., None], asphalt, grass)
    photo[curb] = (185, 185, 180)
    photo[marking] = (235, 235, 230)
    cv2.imwrite(str(folder / "photometric.png"), np.clip(photo, 0, 255).astype(np.uint8))
    cv2.imwrite(str(folder / "semantic.png"), semantic)
    elevation = (0.02 * x + 0.3 * np.sin(y / 12.0)).astype(np.float32)
    np.save(folder / "elevation.npy", elevation)
    counts = np.clip(np.where(road, 40, 6) + rng.integers(0, 8, x.shape), 0, 255).astype(np.uint8)
    cv2.imwrite(str(folder / "observation_count.png"), counts)
    (folder / "georeference.json").write_text(json.dumps(georeference()))
    return folder


def polyline(x0: float, x1: float, y: float, n: int, wiggle: float = 0.0) -> list[list[float]]:
    """An east-west polyline of n vertices from x0 to x1 at y (with a small sine wiggle)."""
    xs = np.linspace(x0, x1, n)
    return [[float(v), float(y + wiggle * np.sin(v / 3.0))] for v in xs]


PROPOSED_BY = "vma-v0003"
"""The model the seeded proposals name (the review panel shows it)."""
PROPOSALS: list[dict[str, Any]] = [
    {"class": "divider", "points": polyline(2, 38, 40, 7), "confidence": 0.93},
    {"class": "divider", "points": polyline(52, 118, 40, 9, 0.2), "confidence": 0.41},
    {"class": "boundary", "points": polyline(2, 118, 20.2, 12), "confidence": 0.72},
    {"class": "boundary", "points": polyline(2, 118, 59.8, 12, 0.3), "confidence": 0.28},
    {
        "class": "ped_crossing",
        "points": [[40, 21], [48, 21], [48, 59], [40, 59], [40, 21]],
        "confidence": 0.86,
    },
    {"class": "divider", "points": polyline(60, 100, 10, 5), "confidence": 0.15},
]


@dataclass
class SeededServer:
    """A running server with users and one registered site holding the proposals."""

    server: ServerProcess
    site_id: int
    headers: dict[str, dict[str, str]]
    raster_dir: Path | None = None
    """The painted BEV rasters the sites are registered on."""

    @property
    def base_url(self) -> str:
        """Root URL of the server."""
        return self.server.base_url

    def client(self) -> httpx.Client:
        """A new HTTP client on the server."""
        return httpx.Client(base_url=self.base_url, timeout=10.0)

    def create(self, body: dict[str, Any], user: str = "ann") -> dict[str, Any]:
        """Create an element through the API as `user`; its JSON."""
        with self.client() as client:
            response = client.post(
                f"/api/sites/{self.site_id}/elements", json=body, headers=self.headers[user]
            )
        response.raise_for_status()
        return dict(response.json())

    def add_site(self, name: str, proposals: list[dict[str, Any]]) -> int:
        """Register another site on the same rasters with these proposals (as the lead), for tests that need
        a site no other test touches; its id."""
        site = {
            "name": name,
            "site_origin_xy": list(SITE_ORIGIN_XY),
            "georeference": georeference(),
            "raster_dir": str(self.raster_dir),
        }
        with self.client() as client:
            response = client.post("/api/sites", json=site, headers=self.headers["lead"])
            response.raise_for_status()
            site_id = int(response.json()["id"])
            bulk = {"elements": [{**p, "source": "proposal"} for p in proposals]}
            client.post(
                f"/api/sites/{site_id}/elements/bulk", json=bulk, headers=self.headers["lead"]
            ).raise_for_status()
        return site_id

    def element(self, element_id: int) -> dict[str, Any]:
        """An element's current version from the API."""
        with self.client() as client:
            response = client.get(
                f"/api/sites/{self.site_id}/elements/{element_id}", headers=self.headers["lead"]
            )
        response.raise_for_status()
        return dict(response.json())

    def wait_element(
        self, element_id: int, check: Callable[[dict[str, Any]], bool], timeout_s: float = 10.0
    ) -> dict[str, Any]:
        """Poll the API until the element passes `check`; AssertionError with the last version otherwise."""
        deadline = time.monotonic() + timeout_s
        while True:
            element = self.element(element_id)
            if check(element):
                return element
            if time.monotonic() > deadline:
                raise AssertionError(f"element {element_id} never reached the expected state: {element}")
            time.sleep(0.1)


def seed(server: ServerProcess, raster_dir: Path) -> SeededServer:
    """Create the users, register the painted site and load the proposals (as the lead)."""
    with httpx.Client(base_url=server.base_url, timeout=30.0) as client:
        admin = login(client)
        for username, role in USERS.items():
            body = {"username": username, "password": PASSWORD, "role": role}
            client.post("/api/users", json=body, headers=admin).raise_for_status()
        headers = {name: login(client, name) for name in USERS} | {"root": admin}
        site = {
            "name": "Test junction",
            "site_origin_xy": list(SITE_ORIGIN_XY),
            "georeference": georeference(),
            "raster_dir": str(write_rasters(raster_dir)),
        }
        response = client.post("/api/sites", json=site, headers=headers["lead"])
        response.raise_for_status()
        site_id = int(response.json()["id"])
        bulk = {"elements": [{**p, "source": "proposal", "model": PROPOSED_BY} for p in PROPOSALS]}
        client.post(
            f"/api/sites/{site_id}/elements/bulk", json=bulk, headers=headers["lead"]
        ).raise_for_status()
    return SeededServer(server=server, site_id=site_id, headers=headers, raster_dir=raster_dir)


@contextmanager
def seeded_server(data_dir: Path, review_url: str = "") -> Iterator[SeededServer]:
    """A `cama serve` process on loopback with the seeded site (its editor linking to a 3D review at
    `review_url` when given, as `cama demo` sets it); stopped afterwards."""
    with pytest.MonkeyPatch.context() as patch:  # the server process inherits the variable at start
        patch.setenv("CAMA_REVIEW_URL", review_url)
        server = ServerProcess(data_dir=data_dir).start()
    try:
        yield seed(server, data_dir / "bev")
    finally:
        server.stop()


def launch_chromium(playwright: Playwright) -> Browser:
    """Debian's headless Chromium; FileNotFoundError naming the path when it is not installed."""
    if not Path(CHROMIUM_PATH).exists():
        raise FileNotFoundError(f"{CHROMIUM_PATH}: Chromium is not installed (`make test` installs it)")
    return playwright.chromium.launch(executable_path=CHROMIUM_PATH, args=CHROMIUM_ARGS, headless=True)


def log_in(page: Page, base_url: str, username: str, hash_route: str = "") -> None:
    """Open the editor's log-in form, submit it and wait for the app to leave the form."""
    page.goto(f"{base_url}/{hash_route}")
    page.fill("#username", username)
    page.fill("#password", PASSWORD)
    page.click("#login-submit")
    page.wait_for_selector("#logout")


def open_editor(
    page: Page, seeded: SeededServer, username: str = "ann", query: str = "", site_id: int | None = None
) -> None:
    """Log in and open the seeded site's (or another site's) editor; waits until the elements are drawn."""
    log_in(page, seeded.base_url, username, f"#/site/{site_id or seeded.site_id}{query}")
    page.wait_for_function("window.camaEditor && window.camaEditor.firstRenderMs !== null")


def centre_on(page: Page, x: float, y: float, resolution_m: float) -> None:
    """Centre the map on site point (x, y) at `resolution_m` metres per pixel."""
    page.evaluate("([x, y, r]) => window.camaEditor.centerOn(x, y, r)", [x, y, resolution_m])


def page_xy(page: Page, x: float, y: float) -> tuple[float, float]:
    """Page coordinates (CSS px) of site point (x, y) on the map."""
    box = page.locator("#map").bounding_box()
    assert box is not None, "the map is not on the page"
    px, py = page.evaluate("([x, y]) => window.camaEditor.pixelOf(x, y)", [x, y])
    return box["x"] + px, box["y"] + py


def drag(page: Page, start: tuple[float, float], end: tuple[float, float], steps: int = 8) -> None:
    """Press at `start`, move to `end` in steps, release (a Modify drag)."""
    page.mouse.move(start[0] - 3, start[1] - 3)
    page.mouse.move(*start)
    page.mouse.down()
    page.mouse.move(*end, steps=steps)
    page.mouse.up()


def select_at(page: Page, seeded: SeededServer, element_id: int, x: float, y: float) -> None:
    """Click site point (x, y) and wait until the element is the selection shown in the review panel."""
    page.mouse.click(*page_xy(page, x, y))
    page.wait_for_selector(f".selected-element[data-id='{element_id}']")


def screenshot(page: Page, name: str) -> Path:
    """Save a screenshot under test-output/editor/."""
    SCREENSHOT_DIR.mkdir(parents=True, exist_ok=True)
    path = SCREENSHOT_DIR / f"{name}.png"
    page.screenshot(path=str(path))
    return path
