"""The HSP rules, each a named function on two cameras (positions and optical axes in global metres).

Paper: keep a KNN neighbour only if |Δz| is small; drop it when the view cones cannot overlap (θ1 > 90° and
θ2 > 90°, θ1 between the optical axes, θ2 between the baseline and the first axis); drop cameras that face each
other close together; keep pairs whose ground footprints overlap enough.
"""

import numpy as np


def _angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    """Angle between two vectors in degrees (0 for a zero vector)."""
    norm = float(np.linalg.norm(a) * np.linalg.norm(b))
    if norm == 0:
        return 0.0
    return float(np.degrees(np.arccos(np.clip(float(np.dot(a, b)) / norm, -1.0, 1.0))))


def height_compatible(center_a: np.ndarray, center_b: np.ndarray, max_dz_m: float) -> bool:
    """The paper's |z_i - z_j| < Δz: cameras on the same road level."""
    return abs(float(center_a[2] - center_b[2])) < max_dz_m


def view_cones_overlap(
    center_a: np.ndarray, axis_a: np.ndarray, center_b: np.ndarray, axis_b: np.ndarray
) -> bool:
    """False when θ1 > 90° and θ2 > 90° (axes opposed and B behind A: the cameras look away from each other)."""
    theta1 = _angle_deg(axis_a, axis_b)
    theta2 = _angle_deg(center_b - center_a, axis_a)
    return not (theta1 > 90.0 and theta2 > 90.0)


def face_to_face(
    center_a: np.ndarray,
    axis_a: np.ndarray,
    center_b: np.ndarray,
    axis_b: np.ndarray,
    *,
    min_angle_deg: float,
    max_distance_m: float,
) -> bool:
    """True for cameras whose axes are nearly opposed, each in front of the other, closer than `max_distance_m`."""
    baseline = center_b - center_a
    if float(np.linalg.norm(baseline)) >= max_distance_m or _angle_deg(axis_a, axis_b) < min_angle_deg:
        return False
    return float(np.dot(baseline, axis_a)) > 0 and float(np.dot(-baseline, axis_b)) > 0
