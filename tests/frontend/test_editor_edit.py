"""Editing in the browser, checked through the API: vertices, drawing, relabelling, review, undo/redo, split/merge."""

from typing import Any

import pytest
from playwright.sync_api import Page, expect

from tests.frontend.editor_browser_helpers import (
    SeededServer,
    centre_on,
    drag,
    open_editor,
    page_xy,
    select_at,
)

pytestmark = pytest.mark.slow  # each test is a few seconds; the shared server and browser start once

RES_M = 0.05
"""Map resolution of the editing tests: 20 px per metre."""


def divider_at(seeded: SeededServer, x0: float, y: float, n: int = 3, step_m: float = 5.0) -> dict[str, Any]:
    """A fresh straight divider of n vertices along +x, made through the API by ann."""
    points = [[x0 + i * step_m, y] for i in range(n)]
    return seeded.create({"class": "divider", "points": points})


def open_on(page: Page, seeded: SeededServer, element: dict[str, Any]) -> None:
    """Open the editor centred on the element's middle and select it (click on its first segment)."""
    open_editor(page, seeded)
    points = element["points"]
    middle = points[len(points) // 2]
    centre_on(page, middle[0], middle[1], RES_M)
    a, b = points[0], points[1]
    select_at(page, seeded, element["id"], (a[0] + b[0]) / 2, (a[1] + b[1]) / 2)


def near(p: list[float], q: tuple[float, float], tol_m: float = 0.15) -> bool:
    return abs(p[0] - q[0]) <= tol_m and abs(p[1] - q[1]) <= tol_m


def test_drag_a_vertex_is_saved(page: Page, seeded: SeededServer) -> None:
    element = divider_at(seeded, 4.0, 66.0)
    open_on(page, seeded, element)
    drag(page, page_xy(page, 9.0, 66.0), page_xy(page, 9.0, 67.5))
    saved = seeded.wait_element(element["id"], lambda e: e["version"] > element["version"])
    assert near(saved["points"][1], (9.0, 67.5)), saved["points"]
    assert near(saved["points"][0], (4.0, 66.0)) and near(saved["points"][2], (14.0, 66.0))
    expect(page.locator("#save-state")).to_have_text("All changes saved")


def test_ctrl_drag_moves_the_selected_element_whole_and_undo_puts_it_back(
    page: Page, seeded: SeededServer
) -> None:
    element = divider_at(seeded, 4.0, 30.0)  # a place of its own
    open_on(page, seeded, element)
    page.keyboard.down("Control")
    drag(page, page_xy(page, 11.5, 30.0), page_xy(page, 11.5, 29.0))  # from a segment: no vertex inserted
    page.keyboard.up("Control")
    moved = seeded.wait_element(element["id"], lambda e: e["version"] > element["version"])
    assert len(moved["points"]) == 3, moved["points"]
    for point, x in zip(moved["points"], (4.0, 9.0, 14.0), strict=True):
        assert near(point, (x, 29.0)), moved["points"]  # every vertex by the same metre
    expect(page.locator("#save-state")).to_have_text("All changes saved")
    page.keyboard.press("Control+z")
    seeded.wait_element(element["id"], lambda e: e["points"] == element["points"])


def test_insert_then_delete_a_vertex(page: Page, seeded: SeededServer) -> None:
    element = divider_at(seeded, 20.0, 66.0)
    open_on(page, seeded, element)
    drag(page, page_xy(page, 22.5, 66.0), page_xy(page, 22.5, 65.0))
    inserted = seeded.wait_element(element["id"], lambda e: len(e["points"]) == 4)
    assert near(inserted["points"][1], (22.5, 65.0)), inserted["points"]
    page.keyboard.down("Alt")
    page.mouse.click(*page_xy(page, 22.5, 65.0))
    page.keyboard.up("Alt")
    removed = seeded.wait_element(element["id"], lambda e: len(e["points"]) == 3)
    assert [p[1] for p in removed["points"]] == [66.0, 66.0, 66.0]


SLOW_PATCH = """
const send = window.fetch.bind(window);
window.fetch = (input, init) =>
  init && init.method === "PATCH"
    ? new Promise((resolve) => setTimeout(resolve, 1500)).then(() => send(input, init))
    : send(input, init);
"""
"""Every PATCH leaves the page 1.5 s late, as on a loaded server."""


def test_a_vertex_deleted_while_its_insertion_is_still_saving_is_deleted(
    page: Page, seeded: SeededServer
) -> None:
    element = divider_at(
        seeded, 20.0, 58.0
    )  # a place of its own: a copy of another test's line is a lint error
    page.add_init_script(SLOW_PATCH)
    open_on(page, seeded, element)
    drag(page, page_xy(page, 22.5, 58.0), page_xy(page, 22.5, 57.0))
    page.wait_for_timeout(300)  # the drag has ended; its save is still on its way
    assert seeded.element(element["id"])["version"] == element["version"]
    page.keyboard.down("Alt")
    page.mouse.click(*page_xy(page, 22.5, 57.0))
    page.keyboard.up("Alt")
    removed = seeded.wait_element(element["id"], lambda e: e["version"] == element["version"] + 2)
    assert [p[1] for p in removed["points"]] == [58.0, 58.0, 58.0]


def test_a_click_on_a_segment_while_a_drag_is_saving_keeps_the_drag_on_the_map(
    page: Page, seeded: SeededServer
) -> None:
    element = divider_at(seeded, 60.0, 50.0)  # a place of its own
    page.add_init_script(SLOW_PATCH)
    open_on(page, seeded, element)
    drag(page, page_xy(page, 65.0, 50.0), page_xy(page, 65.0, 51.0))
    page.wait_for_timeout(300)  # the drag's save is still on its way
    page.mouse.click(*page_xy(page, 67.5, 50.5))  # a plain click on the dragged segment: a selection, no edit
    drawn = page.evaluate("(id) => window.camaEditor.pointsOf(id)", element["id"])
    assert len(drawn) == 3 and near(drawn[1], (65.0, 51.0)), drawn
    saved = seeded.wait_element(element["id"], lambda e: e["version"] > element["version"])
    assert len(saved["points"]) == 3 and near(saved["points"][1], (65.0, 51.0)), saved["points"]


LATE_SINGLE_CLICK = """
const schedule = window.setTimeout.bind(window);
window.setTimeout = (handler, delay, ...args) => schedule(handler, delay === 250 ? 20000 : delay, ...args);
"""
"""OpenLayers' 250 ms single-click timer fires 20 s late, as on a page kept busy: every later click pairs with the
one before it into a double click."""


def test_an_alt_click_paired_into_a_double_click_still_deletes(page: Page, seeded: SeededServer) -> None:
    element = divider_at(seeded, 5.0, 50.0)  # a place of its own
    page.add_init_script(LATE_SINGLE_CLICK)
    open_on(page, seeded, element)  # the selecting click's single-click timer is still pending ...
    drag(page, page_xy(page, 7.5, 50.0), page_xy(page, 7.5, 49.0))
    seeded.wait_element(element["id"], lambda e: len(e["points"]) == 4)
    page.keyboard.down("Alt")
    page.mouse.click(*page_xy(page, 7.5, 49.0))  # ... so this click is the second of a double click
    page.keyboard.up("Alt")
    removed = seeded.wait_element(element["id"], lambda e: len(e["points"]) == 3)
    assert [p[1] for p in removed["points"]] == [50.0, 50.0, 50.0]


def test_an_alt_click_on_a_segment_changes_nothing(page: Page, seeded: SeededServer) -> None:
    element = divider_at(seeded, 5.0, 46.0)
    page.add_init_script(LATE_SINGLE_CLICK)
    open_on(page, seeded, element)
    page.keyboard.down("Alt")
    for x in (11.0, 12.5):  # the second click pairs with the first into a double click
        page.mouse.click(*page_xy(page, x, 46.0))
    page.keyboard.up("Alt")
    drag(page, page_xy(page, 13.5, 46.0), page_xy(page, 13.5, 47.0))  # the line still answers edits
    moved = seeded.wait_element(element["id"], lambda e: e["version"] > element["version"])
    assert len(moved["points"]) == 4 and near(moved["points"][2], (13.5, 47.0)), moved["points"]


def test_draw_a_new_divider(page: Page, seeded: SeededServer) -> None:
    open_editor(page, seeded)
    centre_on(page, 100.0, 70.0, RES_M)
    page.keyboard.press("d")
    expect(page.locator("#mode")).to_contain_text("Drawing divider")
    for x in (95.0, 100.0, 105.0):
        page.mouse.click(*page_xy(page, x, 70.0))
        page.wait_for_timeout(350)
    page.keyboard.press("Enter")
    selected = page.locator(".selected-element[data-cls='divider']")
    expect(selected).to_have_count(1)
    element = seeded.element(int(selected.get_attribute("data-id") or 0))
    assert element["class"] == "divider" and element["author"] == "ann" and element["source"] == "human"
    assert len(element["points"]) == 3
    assert all(near(p, (x, 70.0)) for p, x in zip(element["points"], (95.0, 100.0, 105.0), strict=True))


def test_relabel_with_a_number_key(page: Page, seeded: SeededServer) -> None:
    element = divider_at(seeded, 36.0, 66.0)
    open_on(page, seeded, element)
    page.keyboard.press("3")
    saved = seeded.wait_element(element["id"], lambda e: e["class"] == "boundary")
    assert saved["points"] == element["points"]
    expect(page.locator(f".selected-element[data-id='{element['id']}']")).to_have_attribute(
        "data-cls", "boundary"
    )


def test_accept_fix_and_reject(page: Page, seeded: SeededServer) -> None:
    first = divider_at(seeded, 52.0, 66.0)
    second = divider_at(seeded, 52.0, 68.0)
    third = divider_at(seeded, 52.0, 70.0)
    open_on(page, seeded, first)
    page.keyboard.press("a")
    assert seeded.wait_element(first["id"], lambda e: e["state"] == "accepted")["points"] == first["points"]
    select_at(page, seeded, second["id"], 54.5, 68.0)
    page.keyboard.press("x")
    seeded.wait_element(second["id"], lambda e: e["state"] == "rejected")
    select_at(page, seeded, third["id"], 54.5, 70.0)
    page.click("button.review[data-state='fixed']")
    seeded.wait_element(third["id"], lambda e: e["state"] == "fixed")
    expect(page.locator(f".selected-element[data-id='{third['id']}'] .state")).to_have_text("fixed")


def test_undo_and_redo(page: Page, seeded: SeededServer) -> None:
    element = divider_at(seeded, 68.0, 66.0)
    original = element["points"]
    open_on(page, seeded, element)
    page.keyboard.press("v")
    seeded.wait_element(element["id"], lambda e: e["points"] == original[::-1])
    page.keyboard.press("Control+z")
    seeded.wait_element(element["id"], lambda e: e["points"] == original and e["version"] == 3)
    page.keyboard.press("Control+Shift+z")
    seeded.wait_element(element["id"], lambda e: e["points"] == original[::-1] and e["version"] == 4)
    select_at(page, seeded, element["id"], 70.5, 66.0)
    page.keyboard.press("Delete")
    seeded.wait_element(element["id"], lambda e: e["deleted"])
    page.click("#undo")
    restored = seeded.wait_element(element["id"], lambda e: not e["deleted"])
    assert restored["points"] == original[::-1]
    expect(page.locator("#redo")).to_be_enabled()


def test_split_merge_and_simplify(page: Page, seeded: SeededServer) -> None:
    element = divider_at(seeded, 84.0, 66.0, n=5, step_m=2.5)
    open_on(page, seeded, element)
    page.mouse.move(*page_xy(page, 89.0, 66.0))
    page.keyboard.press("k")
    page.wait_for_selector(".selected-element >> nth=1")
    head = seeded.wait_element(element["id"], lambda e: len(e["points"]) == 3)
    assert near(head["points"][-1], (89.0, 66.0))
    other = next(
        int(i)
        for i in page.locator(".selected-element").evaluate_all("els => els.map(e => e.dataset.id)")
        if int(i) != element["id"]
    )
    tail = seeded.element(other)
    assert tail["class"] == "divider" and len(tail["points"]) == 3 and near(tail["points"][0], (89.0, 66.0))
    page.keyboard.press("m")
    merged = seeded.wait_element(element["id"], lambda e: len(e["points"]) == 5)
    assert near(merged["points"][-1], (94.0, 66.0))
    assert seeded.wait_element(other, lambda e: e["deleted"])
    page.keyboard.press("g")
    simplified = seeded.wait_element(element["id"], lambda e: len(e["points"]) == 2)
    assert near(simplified["points"][0], (84.0, 66.0)) and near(simplified["points"][1], (94.0, 66.0))


def test_draw_a_crosswalk_polygon(page: Page, seeded: SeededServer) -> None:
    open_editor(page, seeded)
    centre_on(page, 100.0, 74.0, RES_M)
    page.keyboard.press("c")
    corners = [(96.0, 72.0), (104.0, 72.0), (104.0, 76.0), (96.0, 76.0)]
    for corner in corners:
        page.mouse.click(*page_xy(page, *corner))
        page.wait_for_timeout(350)
    page.keyboard.press("Enter")
    selected = page.locator(".selected-element[data-cls='ped_crossing']")
    expect(selected).to_have_count(1)
    ring = seeded.element(int(selected.get_attribute("data-id") or 0))["points"]
    assert len(ring) == 5 and ring[0] == ring[-1], ring
    assert all(any(near(p, c) for p in ring) for c in corners), ring


def test_a_dragged_vertex_snaps_to_a_neighbour(page: Page, seeded: SeededServer) -> None:
    anchor = divider_at(seeded, 100.0, 64.0)
    element = divider_at(seeded, 100.0, 62.0)
    open_on(page, seeded, element)
    near_anchor = page_xy(page, 110.0 + 0.2, 64.0 - 0.2)
    drag(page, page_xy(page, 110.0, 62.0), near_anchor)
    saved = seeded.wait_element(element["id"], lambda e: e["version"] > 1)
    assert saved["points"][2] == anchor["points"][2], "the end vertex lands exactly on the neighbour's"
