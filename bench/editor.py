"""Browser editor benchmark: 10,000 vertices loaded, time to first render and frame time while dragging a vertex.

A real `cama serve` on loopback holds the painted 120 m x 80 m test site of the browser tests with N polylines of
V vertices (default 500 x 20 = 10,000). Headless Debian Chromium (software rendering, no GPU) opens the editor
with the whole site in view and the timings are read from the page:
- first render: navigation start -> the element layer's first drawn frame (site, layers and all elements fetched,
  features built and drawn); render complete: -> every visible raster tile drawn too. `cold` is the first
  opening (the server builds the tile pyramids in its `/layers` call), `warm` a second page load;
- drag: one vertex of a selected polyline dragged in DRAG_STEPS pointer moves; per frame, the map's render time
  (precompose -> postcompose, the OpenLayers work per frame) and the interval between animation frames (what the
  user sees; 16.7 ms at 60 Hz is the floor);
- pan: the same two series while the whole-site view is dragged away and back;
- idle: the frame intervals over 2 s with nothing happening (the shared machine's own stalls, a baseline).

Camera panel (`camera_panel`, bench/camera_panel.py): on a reconstructed site served on two cores, the time from
selecting an element to its first image and to four images (views + images, sequential and four at once).

Usage: .venv/bin/python bench/editor.py [--elements 500] [--vertices 20] [--section all|browser|camera-panel]
    [--camera-site data/synthetic/default] [--camera-workspace W]
Prints the figures and writes them to bench/results/editor.json (a section run alone keeps the other's keys).
"""

import argparse
import json
import logging
import os
import platform
import statistics
import sys
import tempfile
from pathlib import Path
from typing import Any

import httpx
from playwright.sync_api import Page, ViewportSize, sync_playwright

# the test helpers: `tests` is a package at the repository root
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from bench import camera_panel  # noqa: E402
from tests.frontend.editor_browser_helpers import (  # noqa: E402
    SITE_SIZE_M,
    SeededServer,
    launch_chromium,
    log_in,
    page_xy,
    seeded_server,
)

logger = logging.getLogger(__name__)
RESULTS = Path(__file__).parent / "results"
DRAG_STEPS = 120
VIEWPORT: ViewportSize = {"width": 1440, "height": 900}


def load_polylines(seeded: SeededServer, n_elements: int, n_vertices: int) -> int:
    """Bulk-load n_elements wavy dividers of n_vertices each across the site; total vertex count."""
    rows = max(1, round((n_elements * SITE_SIZE_M[1] / SITE_SIZE_M[0]) ** 0.5))
    cols = -(-n_elements // rows)
    cell_w, cell_h = SITE_SIZE_M[0] / cols, SITE_SIZE_M[1] / rows
    elements = []
    for index in range(n_elements):
        x0, y0 = (index % cols) * cell_w, (index // cols) * cell_h + cell_h / 2
        step = 0.8 * cell_w / (n_vertices - 1)
        points = [[x0 + 0.1 * cell_w + i * step, y0 + 0.25 * cell_h * ((-1) ** i)] for i in range(n_vertices)]
        elements.append({"class": "divider", "points": points, "confidence": 0.3 + 0.6 * (index % 7) / 6})
    with httpx.Client(base_url=seeded.base_url, timeout=120.0) as client:
        path = f"/api/sites/{seeded.site_id}/elements/bulk"
        body = {"elements": [{**e, "source": "proposal"} for e in elements]}
        response = client.post(path, json=body, headers=seeded.headers["lead"])
    response.raise_for_status()
    return n_elements * n_vertices


def quantiles(values: list[float]) -> dict[str, float] | None:
    """Median, 95th percentile and maximum, rounded to 0.01 ms; None without values (no frame rendered)."""
    if not values:
        return None
    ordered = sorted(values)
    p95 = ordered[min(len(ordered) - 1, round(0.95 * (len(ordered) - 1)))]
    return {
        "median": round(statistics.median(ordered), 2),
        "p95": round(p95, 2),
        "max": round(ordered[-1], 2),
    }


def measure_load(page: Page, seeded: SeededServer) -> dict[str, Any]:
    """Load the editor page afresh (token already in session storage) and read its first-render times."""
    page.goto("about:blank")
    page.goto(f"{seeded.base_url}/#/site/{seeded.site_id}")
    page.wait_for_function(
        "window.camaEditor && window.camaEditor.renderCompleteMs !== null", timeout=120_000
    )
    first, complete = page.evaluate("[window.camaEditor.firstRenderMs, window.camaEditor.renderCompleteMs]")
    fetches = page.evaluate(
        """() => Object.fromEntries(performance.getEntriesByType('resource')
            .filter(e => /api\\/(sites\\/\\d+(\\/layers|\\/elements)?|auth\\/me)(\\?|$)/.test(e.name))
            .map(e => [new URL(e.name).pathname, {start: Math.round(e.startTime), end: Math.round(e.responseEnd)}]))"""
    )
    return {
        "first_render_ms": round(first, 1),
        "render_complete_ms": round(complete, 1),
        "api_fetches_ms": fetches,
    }


def measure_drag(page: Page, seeded: SeededServer, element: dict[str, Any]) -> dict[str, Any]:
    """Select a polyline in the full-site view and drag its middle vertex; per-frame timings."""
    a, b = element["points"][0], element["points"][1]
    page.mouse.click(*page_xy(page, (a[0] + b[0]) / 2, (a[1] + b[1]) / 2))
    page.wait_for_selector(f".selected-element[data-id='{element['id']}']")
    vertex = element["points"][len(element["points"]) // 2]
    start = page_xy(page, *vertex)
    start_recording(page)
    page.mouse.move(start[0] - 2, start[1] - 2)
    page.mouse.move(*start)
    page.mouse.down()
    page.mouse.move(start[0] + 150, start[1] + 90, steps=DRAG_STEPS)
    page.mouse.up()
    page.wait_for_timeout(200)
    figures = stop_recording(page)
    seeded.wait_element(element["id"], lambda e: e["version"] > element["version"])
    return figures


def start_recording(page: Page) -> None:
    """Start collecting per-frame render times and animation-frame intervals in the page."""
    page.evaluate("""() => {
        const hook = window.camaEditor;
        hook.frameRenderMs = [];
        hook.rafMs = [];
        hook.recording = true;
        let last = performance.now();
        const tick = (now) => { hook.rafMs.push(now - last); last = now; if (hook.recording) requestAnimationFrame(tick); };
        requestAnimationFrame(tick);
    }""")


def stop_recording(page: Page) -> dict[str, Any]:
    """Stop collecting; frame count and the quantiles of both series."""
    render, raf = page.evaluate(
        "() => { const h = window.camaEditor; h.recording = false; return [h.frameRenderMs, h.rafMs.slice(1)]; }"
    )
    return {"frames": len(render), "render_ms": quantiles(render), "frame_interval_ms": quantiles(raf)}


def measure_idle(page: Page) -> dict[str, Any]:
    """Frame intervals with nothing happening: the machine's own noise, as a baseline for pan and drag."""
    start_recording(page)
    page.wait_for_timeout(2000)
    return stop_recording(page)


def measure_pan(page: Page) -> dict[str, Any]:
    """Pan the whole-site view by dragging the map (Escape first, so nothing is selected), then back."""
    page.keyboard.press("Escape")
    box = page.locator("#map").bounding_box()
    assert box is not None, "the map is not on the page"
    x, y = box["x"] + box["width"] * 0.3, box["y"] + box["height"] * 0.9
    start_recording(page)
    page.mouse.move(x, y)
    page.mouse.down()
    page.mouse.move(x + 400, y - 250, steps=DRAG_STEPS // 2)
    page.mouse.move(x, y, steps=DRAG_STEPS // 2)
    page.mouse.up()
    page.wait_for_timeout(200)
    return stop_recording(page)


def run(n_elements: int, n_vertices: int) -> dict[str, Any]:
    """Seed a server, load the polylines, measure in Chromium; the figures (with the machine's load, since
    other work on a shared machine shows in the frame times)."""
    load_before = round(os.getloadavg()[0], 2)
    with tempfile.TemporaryDirectory() as tmp, seeded_server(Path(tmp) / "server") as seeded:
        vertices = load_polylines(seeded, n_elements, n_vertices)
        with seeded.client() as client:
            listed = client.get(
                f"/api/sites/{seeded.site_id}/elements",
                params={"limit": 100000},
                headers=seeded.headers["ann"],
            ).json()
        element = next(e for e in listed if len(e["points"]) == n_vertices and e["points"][0][0] > 40)
        with sync_playwright() as playwright:
            browser = launch_chromium(playwright)
            page = browser.new_page(viewport=VIEWPORT, bypass_csp=True)
            log_in(page, seeded.base_url, "ann")
            load = {"cold": measure_load(page, seeded), "warm": measure_load(page, seeded)}
            idle = measure_idle(page)
            pan = measure_pan(page)
            drag = measure_drag(page, seeded, element)
            version = browser.version
            browser.close()
    return {
        "vertices_loaded": vertices,
        "vertices_on_site": sum(len(e["points"]) for e in listed),
        "elements": len(listed),
        "chromium": version,
        "viewport": VIEWPORT,
        "machine": f"{platform.machine()}, {os.cpu_count()} cores, software rendering (no GPU)",
        "load_average_1m_before": load_before,
        "load_average_1m_after": round(os.getloadavg()[0], 2),
        "load": load,
        "idle": idle,
        "pan": pan,
        "drag": drag,
    }


def main() -> None:
    """Parse options, run, print and write bench/results/editor.json."""
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--elements", type=int, default=500)
    parser.add_argument("--vertices", type=int, default=20)
    parser.add_argument("--section", choices=("all", "browser", "camera-panel"), default="all")
    parser.add_argument("--camera-site", type=Path, default=Path("data/synthetic/default"))
    parser.add_argument("--camera-workspace", type=Path, default=None, help="default: the site's workspace")
    args = parser.parse_args()
    if args.elements < 1 or args.vertices < 3:
        raise SystemExit("--elements must be >= 1 and --vertices >= 3")
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    logging.getLogger("httpx").setLevel(logging.WARNING)
    path = RESULTS / "editor.json"
    figures = json.loads(path.read_text()) if path.is_file() else {}
    if args.section in ("all", "browser"):
        figures.update(run(args.elements, args.vertices))
    if args.section in ("all", "camera-panel"):
        figures["camera_panel"] = camera_panel.run(args.camera_site, args.camera_workspace)
    RESULTS.mkdir(exist_ok=True)
    path.write_text(json.dumps(figures, indent=2) + "\n")
    logger.info("%s", json.dumps(figures, indent=2))


if __name__ == "__main__":
    main()
