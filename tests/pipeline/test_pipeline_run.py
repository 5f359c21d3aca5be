"""`cama run`: stages in order with their times; a failure names its stage; the full path on the tiny site."""

import json
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import httpx
import pytest
from playwright.sync_api import sync_playwright
from typer.testing import CliRunner

from annotations.schema import AnnotationSet
from cama_pipeline.cli import app
from cama_pipeline.pipeline import STAGES, PipelineConfig, PipelineError, proposals_path, run

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "frontend"))
from editor_browser_helpers import launch_chromium, log_in, screenshot  # noqa: E402
from system_helpers import PASSWORD, cama_executable, free_port  # noqa: E402


def test_the_path_runs_in_order_up_to_the_asked_stage_and_reruns_skip(
    site_root: Path, tmp_path: Path
) -> None:
    seen: list[str] = []
    result = run(site_root / "nuscenes", tmp_path / "ws", stop_after="sites", on_stage=seen.append)
    assert seen == ["wigo", "keyframes", "sites"] == list(result.seconds)
    index = json.loads((tmp_path / "ws" / "sites" / "index.json").read_text())
    assert index["sites"]
    again = run(site_root / "nuscenes", tmp_path / "ws", stop_after="sites")
    assert again.seconds["wigo"] < result.seconds["wigo"] + 5.0


def test_a_failing_stage_is_named(tmp_path: Path) -> None:
    with pytest.raises(PipelineError, match="stage wigo failed"):
        run(tmp_path / "no-such-dataset", tmp_path / "ws", stop_after="wigo")
    with pytest.raises(ValueError, match="stop_after"):
        run(tmp_path, stop_after="everything")


def test_cama_run_reports_a_bad_option_and_a_missing_dataset(tmp_path: Path) -> None:
    runner = CliRunner()
    bad = runner.invoke(app, ["run", str(tmp_path), "--executor", "cloud"])
    assert bad.exit_code == 1 and "--executor" in bad.output
    missing = runner.invoke(app, ["run", str(tmp_path / "none"), "--stop-after", "wigo"])
    assert missing.exit_code == 1 and "stage wigo failed" in missing.output


@pytest.fixture(scope="module")
def whole_path(tiny_site: Any, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, Path]]:
    """The whole path on the tiny site once: (workspace, proposals by site)."""
    site_root = tiny_site.result.out_dir
    workspace = tmp_path_factory.mktemp("whole-path") / "ws"
    result = run(site_root / "nuscenes", workspace, PipelineConfig(proposer="rule", max_features=1024))
    assert list(result.seconds) == list(STAGES)
    return workspace, result.proposals


@pytest.mark.slow
def test_the_whole_path_on_the_tiny_site_ends_with_proposals(
    whole_path: tuple[Path, dict[str, Path]],
) -> None:
    workspace, proposals = whole_path
    assert proposals
    for site_id, path in proposals.items():
        assert path == proposals_path(workspace, site_id) and path.is_file()
        assert (workspace / "surface" / site_id / "bev" / "semantic.png").is_file()
        assert (workspace / "sfm" / site_id / "points.npz").is_file()


@pytest.mark.slow
def test_the_demo_serves_the_reconstructed_site_to_a_browser(
    site_root: Path, whole_path: tuple[Path, dict[str, Path]], tmp_path: Path
) -> None:
    """`cama demo` as `make demo` runs it, driven once in headless Chromium: log in, open the site, see the
    reconstructed raster tiles and every proposal."""
    workspace, proposals = whole_path
    site_id, proposal_file = next(iter(proposals.items()))
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
        with sync_playwright() as playwright:
            browser = launch_chromium(playwright)
            context = browser.new_context(viewport={"width": 1280, "height": 800}, bypass_csp=True)
            page = context.new_page()
            tiles: list[int] = []
            page.on("response", lambda r: tiles.append(r.status) if "/tiles/" in r.url else None)
            log_in(page, base, "annotator")
            card = page.locator(".site-card").filter(has_text="(reconstructed)")
            card.click()
            page.wait_for_function(
                "window.camaEditor && window.camaEditor.firstRenderMs !== null", timeout=30_000
            )
            assert page.evaluate("window.camaEditor.elementCount()") == expected
            page.wait_for_function(
                "() => performance.getEntriesByType('resource').some(e => e.name.includes('/tiles/photometric/'))"
            )
            screenshot(page, "demo_reconstructed_site")
            browser.close()
        assert tiles and all(status == 200 for status in tiles), tiles
    finally:
        server.terminate()
        server.wait(10)
