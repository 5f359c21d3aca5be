"""The HSP rules, each a named function on two cameras (positions and optical axes in global metres).

Paper: keep a KNN neighbour only if |Δz| is small; drop it when the view cones cannot overlap (θ1 > 90° and
θ2 > 90°, θ1 between the optical axes, θ2 between the baseline and the first axis); drop cameras that face each
other close together; keep pairs whose ground footprints overlap enough.

Every rule takes one pair ((3,) vectors) or many at once ((N, 3) arrays, one row per pair) and answers a bool
or an (N,) bool array: the selection runs them over hundreds of thousands of candidates at once.
"""

import numpy as np

Vectors = np.ndarray
"""(3,) for one pair, (N, 3) for N pairs."""


def _angle_deg(a: Vectors, b: Vectors) -> np.ndarray:
    """Angle between vectors along the last axis, in degrees (0 where either is zero)."""
    norm = np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1)
    cosine = np.einsum("...i,...i->...", a, b) / np.where(norm > 0, norm, 1.0)
    return np.where(norm > 0, np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0))), 0.0)


def height_compatible(center_a: Vectors, center_b: Vectors, max_dz_m: float) -> np.ndarray:
    """The paper's |z_i - z_j| < Δz: cameras on the same road level."""
    return np.asarray(np.abs(center_a[..., 2] - center_b[..., 2]) < max_dz_m)


def view_cones_overlap(center_a: Vectors, axis_a: Vectors, center_b: Vectors, axis_b: Vectors) -> np.ndarray:
    """False when θ1 > 90° and θ2 > 90° (axes opposed and B behind A: the cameras look away from each other)."""
    theta1 = _angle_deg(axis_a, axis_b)
    theta2 = _angle_deg(center_b - center_a, axis_a)
    return np.asarray(~((theta1 > 90.0) & (theta2 > 90.0)))


def face_to_face(
    center_a: Vectors,
    axis_a: Vectors,
    center_b: Vectors,
    axis_b: Vectors,
    *,
    min_angle_deg: float,
    max_distance_m: float,
) -> np.ndarray:
    """True for cameras whose axes are nearly opposed, each in front of the other, closer than `max_distance_m`."""
    baseline = center_b - center_a
    close = np.linalg.norm(baseline, axis=-1) < max_distance_m
    opposed = _angle_deg(axis_a, axis_b) >= min_angle_deg
    a_sees_b = np.einsum("...i,...i->...", baseline, axis_a) > 0
    b_sees_a = np.einsum("...i,...i->...", -baseline, axis_b) > 0
    return np.asarray(close & opposed & a_sees_b & b_sees_a)
