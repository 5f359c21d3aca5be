"""Colours of the 3D view: the editor's class palette (app/frontend/src/editor/styles.js), tinted by review state."""

import numpy as np

CLASS_RGB: dict[str, tuple[int, int, int]] = {
    "divider": (0x38, 0xBD, 0xF8),
    "ped_crossing": (0xE8, 0x79, 0xF9),
    "boundary": (0xF8, 0x71, 0x71),
}
REJECTED_RGB = (120, 120, 120)
RETURNED_RGB = (250, 204, 21)
SELECTED_RGB = (255, 255, 255)
CAMERA_RGB = (34, 197, 94)
VIEW_FRUSTUM_RGB = (251, 146, 60)
"""The selected element's camera views (app/viewer/cameras.py): orange, apart from the green keyframe cameras."""
LIFTED_ELEMENT_RGB = (255, 235, 59)
"""The selected element as the backend lifts it (the line its camera views project): bright yellow."""
_PROPOSED_DIM = 0.55
"""Proposals not yet reviewed are drawn darker than reviewed work, as the editor dims the opposite way."""
SEMANTIC_RGB = np.array(
    [[90, 90, 90], [130, 130, 140], [250, 160, 60], [245, 245, 245], [230, 230, 120]], dtype=np.uint8
)
"""Sparse-point colours by raster class 0..4 (background, road, curb, lane marking, crosswalk)."""


def element_rgb(cls: str, state: str) -> tuple[int, int, int]:
    """The colour of an element: its class colour, dimmed while proposed, grey when rejected, amber when returned."""
    if state == "rejected":
        return REJECTED_RGB
    if state == "returned":
        return RETURNED_RGB
    r, g, b = CLASS_RGB.get(cls, (200, 200, 200))
    if state == "proposed":
        return int(r * _PROPOSED_DIM), int(g * _PROPOSED_DIM), int(b * _PROPOSED_DIM)
    return r, g, b


def semantic_rgb(labels: np.ndarray) -> np.ndarray:
    """(N, 3) uint8 colours of sparse points by raster class; unknown classes (e.g. 255) are dark grey."""
    labels = np.asarray(labels, dtype=np.int64)
    colors = np.full((len(labels), 3), 60, dtype=np.uint8)
    known = (labels >= 0) & (labels < len(SEMANTIC_RGB))
    colors[known] = SEMANTIC_RGB[labels[known]]
    return colors
