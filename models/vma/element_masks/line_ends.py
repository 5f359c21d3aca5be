"""The ends of traced dividers and boundaries: put back on the line's course where they stray sideways, and carried
on to the edge of what the cameras observed where they stop just short of it.

The element-mask network's masks fade towards a line's end, so the traced line's last vertex is pulled across it and
stops before the edge of the observed map, where the truth an annotator draws is cut: both cost the annotator a drag.
Pure functions over (N, 2) polylines in global metres.
"""

import numpy as np

from annotations.geometry import arc_lengths
from cama_pipeline.evaluate.observed import ObservedMask

END_SKIP_M = 0.3
"""The vertices this close to a line's end are not part of the course its end is checked against."""


def _course(end: np.ndarray, distance: np.ndarray, course_m: float) -> np.ndarray:
    """The vertices an end is judged against (`end` starts at the end vertex, `distance` from it): those between
    `END_SKIP_M` and `END_SKIP_M + course_m` along the line."""
    return end[(distance > END_SKIP_M) & (distance <= END_SKIP_M + course_m)]


def straightened_ends(points: np.ndarray, course_m: float, tolerance_m: float) -> np.ndarray:
    """`points` with each end vertex put back on the line's course where it strays from it sideways.

    Where a boundary's band ends (the road's edge turning a corner, or stopping at the end of what the cameras
    saw) the refinement's last station is pulled across the line, often by half a metre or more: a kink an
    annotator has to drag back. The course is the straight line through the vertices between `END_SKIP_M` and
    `END_SKIP_M + course_m` from the end (at least two of them); an end vertex farther than `tolerance_m` off it
    moves onto it, keeping its distance along it. Lines shorter than three times `course_m` are left as they
    are (their ends are most of them)."""
    along = arc_lengths(points)
    if course_m == 0 or along[-1] < 3 * course_m:
        return points
    out = np.array(points, dtype=np.float64)
    for end, distance in ((out, along), (out[::-1], along[-1] - along[::-1])):
        course = _course(end, distance, course_m)
        if len(course) < 2:
            continue
        direction = course[0] - course[-1]
        direction /= max(float(np.linalg.norm(direction)), 1e-9)
        normal = np.array([-direction[1], direction[0]])
        off = float((end[0] - course[0]) @ normal)
        if abs(off) > tolerance_m:
            end[0] = end[0] - off * normal
    return out


BORDER_STEP_M = 0.05
"""Spacing of the probes that look for the edge of the observed cells ahead of a line's end."""
FIT_STEP_M = 0.1
"""Spacing of the points a line's end stretch is resampled at for its fitted course."""


def fitted_course(end: np.ndarray, distance: np.ndarray, fit_m: float) -> tuple[np.ndarray, np.ndarray]:
    """(point, unit direction) of the straight line fitted to the stretch within `fit_m` of an end (`end` starts at
    the end vertex, `distance` from it), resampled every `FIT_STEP_M` so that closely spaced vertices do not weigh
    more: its principal axis through its mean, pointing out of the line past the end."""
    stations = np.linspace(0.0, min(fit_m, float(distance[-1])), max(2, int(fit_m / FIT_STEP_M) + 1))
    stretch = np.column_stack([np.interp(stations, distance, end[:, k]) for k in (0, 1)])
    centre = stretch.mean(axis=0)
    direction = np.linalg.svd(stretch - centre)[2][0]
    return centre, direction if direction @ (stretch[0] - stretch[-1]) >= 0 else -direction


def carried_to_border(
    points: np.ndarray,
    observed: ObservedMask,
    course_m: float,
    reach_m: float,
    min_m: float,
    *,
    fit_m: float = 0.0,
    tolerance_m: float = 0.0,
) -> np.ndarray:
    """`points` with a vertex added beyond each end that stops short of the edge of the observed cells, on the
    edge, where the edge lies between `min_m` and `reach_m` straight ahead.

    Lines that run off the observed map are cut at its edge in the truth an annotator draws (what the cameras saw,
    `cama_pipeline.evaluate.observed`), but the network's masks fade out before that edge, so the traced line
    stops short and the annotator drags each such end out to it: on the tuning reconstructions 9116-9127 these
    were a third of the boundary fixes. Ahead is the direction from the end's course (its farthest vertex within
    `END_SKIP_M + course_m`, else its neighbour) to the end. An edge farther ahead than `reach_m` means the line
    ends inside the observed map, a real end, left alone; carries shorter than `min_m` gained nothing there and
    tipped accepted lines into fixes.

    With `fit_m` > 0 ahead is instead the course fitted to the line's last `fit_m` (`fitted_course`), and a
    carried end that lies farther than `tolerance_m` off that course is first put on it: the end vertex of a
    traced line is often pulled a few decimetres sideways where its mask fades, and a carry of several metres
    along that kink lands a metre off the line (dividers, `MaskInferenceConfig.divider_border_reach_m`)."""
    if reach_m == 0 or len(points) < 2:
        return points
    out = np.array(points, dtype=np.float64)
    along = arc_lengths(out)
    probes = np.arange(BORDER_STEP_M, reach_m + BORDER_STEP_M / 2, BORDER_STEP_M)
    ends = []
    for end, distance in ((out, along), (out[::-1], along[-1] - along[::-1])):
        start, direction = _ahead(end, distance, course_m, fit_m, tolerance_m)
        carried = None
        if direction is not None:
            ahead = start + probes[:, None] * direction
            seen = observed.contains(ahead)
            first_unseen = int(np.argmax(~seen))
            if not seen.all() and first_unseen > 0 and probes[first_unseen - 1] >= min_m:
                carried = (start, ahead[first_unseen - 1])
        ends.append(carried)
    first, last = ends
    if first is not None:
        out[0] = first[0]
    if last is not None:
        out[-1] = last[0]
    parts = [out]
    if first is not None:
        parts.insert(0, first[1][None])
    if last is not None:
        parts.append(last[1][None])
    return np.vstack(parts)


def _ahead(
    end: np.ndarray, distance: np.ndarray, course_m: float, fit_m: float, tolerance_m: float
) -> tuple[np.ndarray, np.ndarray | None]:
    """(where the carry starts, its unit direction or None) at one end of a line (see `carried_to_border`)."""
    if fit_m > 0 and distance[-1] > 0:
        centre, direction = fitted_course(end, distance, fit_m)
        normal = np.array([-direction[1], direction[0]])
        off = float((end[0] - centre) @ normal)
        return (end[0] - off * normal if abs(off) > tolerance_m else end[0]), direction
    course = _course(end, distance, course_m)
    behind = course[-1] if len(course) else end[1]
    direction = end[0] - behind
    length = float(np.linalg.norm(direction))
    return end[0], (direction / length if length > 1e-6 else None)
