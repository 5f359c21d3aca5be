"""`make demo`'s last step, driven once in the browser: `cama demo` serving a site reconstructed by the whole
path (the tiny site's `cama run` outputs: surface rasters and proposals)."""

import os
import subprocess
import time
from pathlib import Path

import httpx
import pytest
from playwright.sync_api import Page

from annotations.schema import AnnotationSet
from cama_studio.pipeline import PipelineResult
from tests.backend_system.system_helpers import PASSWORD, cama_executable, free_port
from tests.frontend.editor_browser_helpers import log_in, screenshot


@pytest.mark.slow
def test_the_demo_serves_the_reconstructed_site_to_a_browser(
    site_root: Path, whole_path: PipelineResult, page: Page, tmp_path: Path
) -> None:
    """`cama demo` as `make demo` runs it, driven once in headless Chromium: log in, open the site, see the
    reconstructed raster tiles and every proposal."""
    workspace = whole_path.workspace
    site_id, proposal_file = next(iter(whole_path.proposals.items()))
    port = free_port()
    command = [str(cama_executable()), "demo", str(site_root), "--proposals", str(proposal_file)]
    command += [
        "--rasters",
        str(workspace / "surface" / site_id / "bev"),
        "--data-dir",
        str(tmp_path / "server"),
    ]
    command += ["--port", str(port), "--view-port", "0"]
    log = (tmp_path / "demo.log").open("wb")
    server = subprocess.Popen(
        command, env={**os.environ, "CAMA_DEMO_PASSWORD": PASSWORD}, stdout=log, stderr=log
    )
    base = f"http://127.0.0.1:{port}"
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            try:
                if httpx.get(f"{base}/openapi.json", timeout=2).status_code == 200:
                    break
            except httpx.HTTPError:
                time.sleep(0.5)
        else:
            pytest.fail(f"cama demo did not answer: {(tmp_path / 'demo.log').read_text()[-2000:]}")
        expected = len(AnnotationSet.read_json(proposal_file).elements)
        tiles: list[int] = []
        page.on("response", lambda r: tiles.append(r.status) if "/tiles/" in r.url else None)
        log_in(page, base, "annotator")
        page.locator(".site-card").filter(has_text="(reconstructed)").click()
        page.wait_for_function(
            "window.camaEditor && window.camaEditor.firstRenderMs !== null", timeout=30_000
        )
        assert page.evaluate("window.camaEditor.elementCount()") == expected
        page.wait_for_function(
            "() => performance.getEntriesByType('resource').some(e => e.name.includes('/tiles/photometric/'))"
        )
        screenshot(page, "demo_reconstructed_site")
        assert tiles and all(status == 200 for status in tiles), tiles
    finally:
        server.terminate()
        server.wait(10)
