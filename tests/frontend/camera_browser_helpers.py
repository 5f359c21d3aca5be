"""Helpers of the camera-panel browser tests: a site registered on the tiny synthetic site with its
reconstruction (images, SfM poses, lane masks), its ground-truth map loaded as proposals, and what a panel's
canvas shows, read back as pixels.

The ground-truth divider `gt-0005` (straight, y = 0 m, x -40..-18.5 m in site metres) is left out of the loaded
map: tests draw their own dividers on it.
"""

import base64
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from playwright.sync_api import Page

from tests.frontend.editor_browser_helpers import SeededServer

FREE_DIVIDER_ID = "gt-0005"
"""The ground-truth divider not loaded: straight along y = 0 from x = -40 to -18.5 (site metres)."""
ELEMENT_RGB = (255, 230, 0)
"""The colour the panel draws the selected element in (camera-view.js ELEMENT_COLOR)."""


@dataclass(frozen=True)
class CameraSite:
    """A registered site with cameras: its id and the loaded ground-truth elements' ids by ground-truth id."""

    site_id: int
    element_ids: dict[str, int]


def ground_truth_elements(synthetic_dir: Path) -> list[dict[str, Any]]:
    """The site's ground-truth map as API element bodies in site metres (gt-0005 left out), each with its
    ground-truth id under `gt`."""
    origin = json.loads((synthetic_dir / "manifest.json").read_text())["config"]["site_origin_xy"]
    vector_map = json.loads((synthetic_dir / "ground_truth" / "vector_map.json").read_text())
    return [
        {
            "gt": e["id"],
            "class": e["class"],
            "points": [[p[0] - origin[0], p[1] - origin[1]] for p in e["points"]],
            "confidence": 0.9,
        }
        for e in vector_map["elements"]
        if e["id"] != FREE_DIVIDER_ID
    ]


def register_camera_site(seeded: SeededServer, synthetic_dir: Path, workspace: Path, name: str) -> CameraSite:
    """Register the synthetic site (its ground-truth rasters) with `workspace`'s SfM poses and load its
    ground-truth map as proposals (as the lead)."""
    body = {"name": name, "synthetic_dir": str(synthetic_dir), "workspace_dir": str(workspace)}
    elements = ground_truth_elements(synthetic_dir)
    with seeded.client() as client:
        response = client.post("/api/sites", json=body, headers=seeded.headers["lead"])
        response.raise_for_status()
        site_id = int(response.json()["id"])
        bulk = {
            "elements": [{k: v for k, v in e.items() if k != "gt"} | {"source": "proposal"} for e in elements]
        }
        created = client.post(
            f"/api/sites/{site_id}/elements/bulk", json=bulk, headers=seeded.headers["lead"]
        )
        created.raise_for_status()
    records = created.json()
    return CameraSite(site_id, {e["gt"]: int(r["id"]) for e, r in zip(elements, records, strict=True)})


def page_fetch(page: Page, path: str) -> tuple[int, bytes]:
    """GET `path` from the page with the logged-in user's token: the status and the body."""
    status, body = page.evaluate(
        """async (path) => {
            const token = sessionStorage.getItem("cama.token");
            const response = await fetch(path, {headers: {Authorization: `Bearer ${token}`}});
            const bytes = new Uint8Array(await response.arrayBuffer());
            let text = "";
            for (let i = 0; i < bytes.length; i += 8192) text += String.fromCharCode(...bytes.subarray(i, i + 8192));
            return [response.status, btoa(text)];
        }""",
        path,
    )
    return int(status), base64.b64decode(body)


def decode(data: bytes, flags: int = cv2.IMREAD_COLOR) -> np.ndarray:
    """An encoded image (PNG, JPEG) as an array; AssertionError when it is not one."""
    image = cv2.imdecode(np.frombuffer(data, np.uint8), flags)
    assert image is not None, f"not an image ({len(data)} bytes)"
    return image


def canvas_rgb(page: Page, index: int) -> np.ndarray:
    """The pixels (H, W, 3 RGB) of the panel's `index`-th view canvas."""
    url = page.evaluate(
        "(i) => document.querySelectorAll('#camera-grid canvas')[i].toDataURL('image/png')", index
    )
    return decode(base64.b64decode(url.split(",", 1)[1]))[..., ::-1]


def drawn_element(canvas: np.ndarray, image: np.ndarray) -> np.ndarray:
    """(H, W) bool: the pixels where the canvas shows the element's colour and the bare image does not."""
    colour = np.array(ELEMENT_RGB, dtype=np.float32)
    on_canvas = np.linalg.norm(canvas.astype(np.float32) - colour, axis=-1) < 60
    in_image = np.linalg.norm(image.astype(np.float32) - colour, axis=-1) < 90
    return on_canvas & ~in_image


def mask_share(drawn: np.ndarray, lane_mask_rgba: np.ndarray, tolerance_px: int = 2) -> float:
    """The share of drawn pixels within `tolerance_px` of a lane-mask pixel (alpha > 0)."""
    mask = (lane_mask_rgba[..., 3] > 0).astype(np.uint8)
    size = 2 * tolerance_px + 1
    near = cv2.dilate(mask, np.ones((size, size), np.uint8)) > 0
    return float(near[drawn].mean()) if drawn.any() else 0.0


def view_on_mask(page: Page, site_id: int, index: int, token: str) -> tuple[int, float]:
    """For the `index`-th view (image `token`, drawn at full size): how many pixels show the element and the
    share of them on the image's lane mask."""
    base = f"/api/sites/{site_id}/images/{token}"
    status, jpeg = page_fetch(page, base)
    assert status == 200, f"image {token}: HTTP {status}"
    status, png = page_fetch(page, f"{base}/lane-mask")
    assert status == 200, f"lane mask {token}: HTTP {status}"
    canvas = canvas_rgb(page, index)
    image = decode(jpeg)[..., ::-1]
    mask = decode(png, cv2.IMREAD_UNCHANGED)
    assert canvas.shape[:2] == image.shape[:2] == mask.shape[:2], (canvas.shape, image.shape, mask.shape)
    drawn = drawn_element(canvas, image)
    return int(drawn.sum()), mask_share(drawn, mask)
