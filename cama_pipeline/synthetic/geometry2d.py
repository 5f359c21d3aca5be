"""Small 2D path helpers for building roads and routes (shapely does the rest)."""

import numpy as np
from shapely.geometry import LineString
from shapely.ops import substring


def arc_points(
    center: tuple[float, float], radius: float, start_rad: float, end_rad: float, step_m: float = 0.5
) -> np.ndarray:
    """Points on a circular arc from `start_rad` to `end_rad` (counter-clockwise if end > start)."""
    n = max(2, int(abs(end_rad - start_rad) * radius / step_m) + 1)
    angles = np.linspace(start_rad, end_rad, n)
    return np.stack([center[0] + radius * np.cos(angles), center[1] + radius * np.sin(angles)], axis=1)


def rounded_polyline(points: np.ndarray, radius: float, step_m: float = 0.5) -> LineString:
    """A polyline through `points` whose corners are replaced by circular arcs of `radius` (a drivable path)."""
    pts = np.asarray(points, dtype=float)
    out = [pts[0]]
    for i in range(1, len(pts) - 1):
        d_in = pts[i] - pts[i - 1]
        d_out = pts[i + 1] - pts[i]
        d_in /= np.linalg.norm(d_in)
        d_out /= np.linalg.norm(d_out)
        turn = np.arctan2(d_in[0] * d_out[1] - d_in[1] * d_out[0], float(d_in @ d_out))
        if abs(turn) < 1e-6:
            out.append(pts[i])
            continue
        cut = radius * np.tan(abs(turn) / 2)
        start = pts[i] - d_in * cut
        normal = np.array([-d_in[1], d_in[0]]) * np.sign(turn)
        center = start + normal * radius
        a0 = np.arctan2(start[1] - center[1], start[0] - center[0])
        out.extend(arc_points((center[0], center[1]), radius, a0, a0 + turn, step_m))
    out.append(pts[-1])
    return LineString(np.asarray(out))


def dashes(line: LineString, dash_m: float, gap_m: float, phase_m: float = 0.0) -> list[LineString]:
    """Cut `line` into painted dashes of `dash_m` separated by `gap_m`."""
    period = dash_m + gap_m
    out: list[LineString] = []
    s = -(phase_m % period)
    while s < line.length:
        a, b = max(s, 0.0), min(s + dash_m, line.length)
        if b - a > 0.2:
            out.append(substring(line, a, b))
        s += period
    return out


def resample(line: LineString, spacing_m: float) -> np.ndarray:
    """Points along `line` every `spacing_m` (ends included)."""
    n = max(2, int(np.ceil(line.length / spacing_m)) + 1)
    return np.array([line.interpolate(s).coords[0] for s in np.linspace(0.0, line.length, n)])
