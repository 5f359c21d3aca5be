"""Lead views: the confidence queue (order, filters, approve/return, open in the editor), figures, jobs."""

from dataclasses import replace
from pathlib import Path

import pytest
from playwright.sync_api import Page, expect

from app.backend.config import Settings
from app.backend.jobs.vma import unavailable_kinds
from cama_pipeline.export import ExportFormat
from tests.frontend.editor_browser_helpers import SeededServer, log_in, screenshot

_SERVED = Settings.from_env()
UNAVAILABLE_KINDS = unavailable_kinds(
    _SERVED if _SERVED.vma_registry else replace(_SERVED, vma_registry=Path("seeded-by-cama-serve"))
)
"""What the served backend (same environment) refuses: `cama serve` seeds a VMA registry in its data folder when
none is configured, so without CAMA_VMA_VALIDATION_SITES retrain is refused for want of a held-out gate."""

pytestmark = pytest.mark.slow  # each test is a few seconds; the shared server and browser start once


def open_lead(page: Page, seeded: SeededServer) -> None:
    log_in(page, seeded.base_url, "lead", f"#/site/{seeded.site_id}/lead")
    expect(page.locator("#queue-table tbody tr.queue-row").first).to_be_visible()


def review(seeded: SeededServer, element_id: int, state: str, user: str = "ann") -> None:
    """Move an element to a review state through the API."""
    with seeded.client() as client:
        version = seeded.element(element_id)["version"]
        path = f"/api/sites/{seeded.site_id}/elements/{element_id}/review"
        response = client.post(path, json={"state": state, "version": version}, headers=seeded.headers[user])
    assert response.status_code == 200, response.text


def test_queue_is_in_confidence_order_and_filters(page: Page, seeded: SeededServer) -> None:
    open_lead(page, seeded)
    rows = page.locator("#queue-table tbody tr.queue-row")
    confidences = rows.evaluate_all("rows => rows.map(r => r.dataset.confidence)")
    scored = [float(c) for c in confidences if c]
    assert len(scored) >= 5 and scored == sorted(scored), confidences
    drawn_first = next((i for i, c in enumerate(confidences) if not c), len(confidences))
    assert all(not c for c in confidences[drawn_first:]), "drawn elements (no confidence) come last"
    figures = page.locator("#figures")
    expect(figures).to_be_visible()
    screenshot(page, "queue")
    page.select_option("#filter-class", "boundary")
    expect(rows.first.locator("td").nth(1)).to_have_text("Boundary")
    classes = rows.evaluate_all("rows => rows.map(r => r.children[1].textContent)")
    assert classes and set(classes) == {"Boundary"}


def test_approve_return_and_open_in_editor(page: Page, seeded: SeededServer) -> None:
    first = seeded.create({"class": "divider", "points": [[60.0, 78.0], [65.0, 78.0]]})
    second = seeded.create({"class": "divider", "points": [[70.0, 78.0], [75.0, 78.0]]})
    review(seeded, first["id"], "accepted")
    review(seeded, second["id"], "fixed")
    open_lead(page, seeded)
    page.select_option("#filter-state", "accepted")
    page.locator(f"tr.queue-row[data-id='{first['id']}'] button.approved").click()
    seeded.wait_element(first["id"], lambda e: e["state"] == "approved")
    page.select_option("#filter-state", "fixed")
    page.locator(f"tr.queue-row[data-id='{second['id']}'] button.returned").click()
    seeded.wait_element(second["id"], lambda e: e["state"] == "returned")
    page.select_option("#filter-state", "")
    page.locator(f"tr.queue-row[data-id='{second['id']}'] td").first.click()
    page.wait_for_function("window.camaEditor && window.camaEditor.firstRenderMs !== null")
    expect(page.locator(f".selected-element[data-id='{second['id']}']")).to_have_count(1)


def export_a_lanelet2_map(page: Page, seeded: SeededServer) -> None:
    """Every export format is offered; a refined-pose MapTR export of the painted site (no reconstruction) is
    refused with the reason shown; a malformed origin is refused before submission; a Lanelet2 export at a nuScenes
    location's origin (no poses) is queued with the origin and the projection chosen."""
    offered = page.locator("#export-format option").evaluate_all("options => options.map(o => o.value)")
    assert offered == [choice.value for choice in ExportFormat]
    page.select_option("#export-format", "maptr")
    expect(page.locator("#export-origin")).to_be_hidden()
    assert seeded.raster_dir is not None
    page.fill("#export-dataset", str(seeded.raster_dir.parent))  # a folder inside the server's data roots
    page.click("#launch-export")
    message = page.locator("#job-message")
    expect(message).to_have_class("job-message error")
    expect(message).to_contain_text("poses: site 'Test junction' has no reconstruction")
    page.select_option("#export-format", "lanelet2")
    expect(page.locator("#export-poses")).to_be_hidden()
    expect(page.locator("#export-dataset")).to_be_hidden()
    page.fill("#export-origin", "1.299, 103.788, 7")
    page.click("#launch-export")
    expect(message).to_have_class("job-message error")
    expect(message).to_contain_text("origin: expected lat, lon in degrees")
    page.fill("#export-origin", "boston-seaport")
    page.select_option("#export-projection", "local")
    with page.expect_request(lambda r: r.url.endswith("/jobs") and r.method == "POST") as submitted:
        page.click("#launch-export")
    params = submitted.value.post_data_json["params"]
    assert params == {"format": "lanelet2", "origin_location": "boston-seaport", "projection": "local"}
    expect(message).to_have_class("job-message")
    expect(message).to_contain_text("export job #")


def test_figures_chart_and_jobs(page: Page, seeded: SeededServer) -> None:
    element = seeded.create({"class": "boundary", "points": [[80.0, 78.0], [85.0, 78.0]]})
    review(seeded, element["id"], "accepted", "bob")
    open_lead(page, seeded)
    chart = page.locator("#figures svg.chart")
    expect(chart).to_be_visible()
    expect(chart.locator("text.chart-label", has_text="bob")).to_have_count(1)
    expect(page.locator("#figures .figures-table td.author", has_text="bob").first).to_be_visible()
    page.click("#launch-retrain")
    if "retrain" in UNAVAILABLE_KINDS:  # the backend refuses with 422 without validation sites
        expect(page.locator("#job-message")).to_have_class("job-message error")
        expect(page.locator("#job-message")).to_contain_text(UNAVAILABLE_KINDS["retrain"])
        expect(page.locator("#job-message")).not_to_contain_text("kind: kind:")
    else:
        expect(page.locator("#job-list .job").first).to_contain_text("retrain")
    export_a_lanelet2_map(page, seeded)
    job = page.locator("#job-list .job").first
    expect(job).to_have_attribute("data-state", "succeeded", timeout=30_000)
    expect(job.locator(".job-text")).to_contain_text("100%")
    expect(job.locator(".download")).to_be_visible()
    expect(
        page.locator("#launch-refresh")
    ).to_be_visible()  # not clicked: the session's shared site stays as seeded
    screenshot(page, "lead")
