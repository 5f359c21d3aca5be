"""Tracing a binary mask's skeleton into ordered pixel paths (one per branch between ends and junctions)."""

import numpy as np
from scipy import ndimage
from skimage.morphology import skeletonize

_NEIGHBOURS = [(dr, dc) for dr in (-1, 0, 1) for dc in (-1, 0, 1) if (dr, dc) != (0, 0)]


def skeleton_paths(mask: np.ndarray, min_pixels: int = 3) -> list[np.ndarray]:
    """Ordered (col, row) pixel paths of the skeleton of `mask`, split at junctions; short stubs dropped."""
    skeleton = skeletonize(mask.astype(bool))
    degree = ndimage.convolve(skeleton.astype(np.uint8), np.ones((3, 3), np.uint8), mode="constant") - 1
    branches = skeleton & ~((degree > 2) & skeleton)
    labels, count = ndimage.label(branches, structure=np.ones((3, 3)))
    paths = []
    for index, slices in enumerate(ndimage.find_objects(labels), start=1):
        if slices is None:
            continue
        rows, cols = np.nonzero(labels[slices] == index)
        if rows.size < min_pixels:
            continue
        rows, cols = rows + slices[0].start, cols + slices[1].start
        paths.append(_order(rows, cols))
    return paths


def _order(rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """The pixels of one branch in walking order, from an end (a pixel with one neighbour) when there is one."""
    pixels = set(zip(rows.tolist(), cols.tolist(), strict=True))

    def neighbours(p: tuple[int, int]) -> list[tuple[int, int]]:
        return [(p[0] + dr, p[1] + dc) for dr, dc in _NEIGHBOURS if (p[0] + dr, p[1] + dc) in pixels]

    ends = [p for p in pixels if len(neighbours(p)) <= 1]
    start = min(ends) if ends else min(pixels)
    order = [start]
    seen = {start}
    while True:
        candidates = [q for q in neighbours(order[-1]) if q not in seen]
        if not candidates:
            break
        # prefer 4-connected steps so diagonal shortcuts do not skip a pixel of the branch
        nxt = min(candidates, key=lambda q: abs(q[0] - order[-1][0]) + abs(q[1] - order[-1][1]))
        order.append(nxt)
        seen.add(nxt)
    return np.array([(c, r) for r, c in order], dtype=np.float64)
