"""A reconstruction's surface as each key frame's own ego frame holds it: what the training code reading an export
sees.

The MapTR and nuScenes-CAMAv2 exports give every sample its map vectors in that sample's (refined) ego frame, with
z read from the elevation raster. A consumer never sees where the whole site sits in the global frame: a height
offset, tilt or shift that the poses and the surface share (WIGO's gauge, which SfM inherits, stands 2-3 cm high
on the synthetic sites) cancels when the surface is carried into the ego frame of a pose in that same frame. What
stays is the surface relative to the vehicle, and that is what this module measures.

For each key frame, every scored surface point is carried into the ego frame by the reconstruction's pose. The
truth is read where the true pose puts that ego-frame point: the true ground's class there, and its height carried
into the true ego frame. Only points inside MapTR's perception range are kept (x in [-30, 30] m forward, y in
[-15, 15] m left), so each key frame scores what its own sample's labels would cover, and a point counts once for
every key frame that has it in range, as the samples of a training set do.
"""

from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass

import numpy as np

from annotations.geometry import MAPTR_RANGE, Box
from cama_pipeline.semantics import Semantic

RANGE_BANDS_M = ((0.0, 5.0), (5.0, 10.0), (10.0, 15.0), (15.0, 20.0), (20.0, 34.0))
"""Bands of planar distance from the ego origin that the height errors are also summarised by."""


@dataclass(frozen=True)
class EgoPairs:
    """The points of one key frame inside the perception range."""

    index: np.ndarray
    """(M,) which of the scored points these are."""
    ego_xyz: np.ndarray
    """(M, 3) the points in the key frame's ego frame, carried by the reconstruction's pose."""
    true_world_xyz: np.ndarray
    """(M, 3) where the true pose puts those ego-frame points in the true global frame."""
    true_world_from_ego: np.ndarray
    """(4, 4) the key frame's true pose."""


@dataclass(frozen=True)
class EgoHeightErrors:
    """Signed height errors (reconstruction minus truth, metres) of surface points in key frames' ego frames."""

    error_m: np.ndarray
    """(N,) one per (key frame, point) pair inside the perception range where the truth has a height."""
    world_error_m: np.ndarray
    """(N,) the same pairs' error in the global frame: the point's z minus the true height at its global x, y (NaN
    where the truth has none there), the figure the shared offset and tilt are not taken out of."""
    distance_m: np.ndarray
    """(N,) the point's planar distance from that key frame's ego origin."""
    keyframes: int
    """Key frames posed by both the reconstruction and the truth."""

    def summary(self) -> dict[str, object]:
        """RMSE, median signed error, 95th percentile of |error|, per distance band too (cm), and counts; the same
        pairs' figures in the global frame beside them."""
        world = self.world_error_m[np.isfinite(self.world_error_m)]
        return {
            "keyframes": self.keyframes,
            "pairs": int(len(self.error_m)),
            **_figures(self.error_m),
            "same_pairs_in_global_frame": _figures(world),
            "by_distance_m": {
                f"{lo:g}-{hi:g}": _figures(self.error_m[(self.distance_m >= lo) & (self.distance_m < hi)])
                for lo, hi in RANGE_BANDS_M
            },
        }


def _figures(error_m: np.ndarray) -> dict[str, float | None]:
    if len(error_m) == 0:
        return {"rmse_cm": None, "median_signed_cm": None, "p95_abs_cm": None}
    return {
        "rmse_cm": float(np.sqrt(np.mean(error_m**2)) * 100),
        "median_signed_cm": float(np.median(error_m) * 100),
        "p95_abs_cm": float(np.percentile(np.abs(error_m), 95) * 100),
    }


def _transform(matrix: np.ndarray, points: np.ndarray) -> np.ndarray:
    return points @ matrix[:3, :3].T + matrix[:3, 3]


def _checked_points(points_xyz: np.ndarray) -> np.ndarray:
    points = np.asarray(points_xyz, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"points_xyz: expected (N, 3) global x, y, z, got shape {points.shape}")
    return points


def ego_pairs(
    points_xyz: np.ndarray,
    world_from_ego: Mapping[str, np.ndarray],
    true_world_from_ego: Mapping[str, np.ndarray],
    box: Box = MAPTR_RANGE,
) -> Iterator[EgoPairs]:
    """For every key frame both pose maps hold (key -> 4x4 world_from_ego), in key order: the (N, 3) points
    (global metres, in the reconstruction's frame) inside `box` of its ego frame, and where the truth has them.
    ValueError naming the argument when the points are not (N, 3) or no key frame is posed by both."""
    points = _checked_points(points_xyz)
    keys = sorted(set(world_from_ego) & set(true_world_from_ego))
    if not keys:
        raise ValueError("world_from_ego and true_world_from_ego: no key frame is posed by both")
    for key in keys:
        ego = _transform(np.linalg.inv(world_from_ego[key]), points)
        inside = (
            (ego[:, 0] >= box.xmin)
            & (ego[:, 0] <= box.xmax)
            & (ego[:, 1] >= box.ymin)
            & (ego[:, 1] <= box.ymax)
        )
        true = true_world_from_ego[key]
        yield EgoPairs(np.flatnonzero(inside), ego[inside], _transform(true, ego[inside]), true)


def ego_height_errors(
    points_xyz: np.ndarray,
    world_from_ego: Mapping[str, np.ndarray],
    true_world_from_ego: Mapping[str, np.ndarray],
    true_height: Callable[[np.ndarray], np.ndarray],
    box: Box = MAPTR_RANGE,
) -> EgoHeightErrors:
    """The height errors of (N, 3) reconstructed surface points in the ego frame of every key frame both pose maps
    hold (`ego_pairs`); `true_height` maps (M, 2) true global x, y to the true ground height there, NaN where it
    has none to compare (not road, say)."""
    points = _checked_points(points_xyz)
    world_error = points[:, 2] - true_height(points[:, :2])
    errors, world_errors, distances, keyframes = [], [], [], 0
    for pairs in ego_pairs(points, world_from_ego, true_world_from_ego, box):
        true_world = pairs.true_world_xyz.copy()
        true_world[:, 2] = true_height(true_world[:, :2])
        known = np.isfinite(true_world[:, 2])
        true_ego = _transform(np.linalg.inv(pairs.true_world_from_ego), true_world[known])
        errors.append(pairs.ego_xyz[known, 2] - true_ego[:, 2])
        world_errors.append(world_error[pairs.index[known]])
        distances.append(np.linalg.norm(pairs.ego_xyz[known, :2], axis=1))
        keyframes += 1
    return EgoHeightErrors(
        np.concatenate(errors), np.concatenate(world_errors), np.concatenate(distances), keyframes
    )


def ego_class_iou(
    points_xyz: np.ndarray,
    labels: np.ndarray,
    world_from_ego: Mapping[str, np.ndarray],
    true_world_from_ego: Mapping[str, np.ndarray],
    true_label: Callable[[np.ndarray], np.ndarray],
    classes: Mapping[str, int],
    box: Box = MAPTR_RANGE,
) -> dict[str, dict[str, float | None]]:
    """IoU per named class over the (key frame, point) pairs in range (`ego_pairs`): each point's label (N,)
    against the true class where the true pose puts it (`ego`), and the same pairs against the true class at the
    point's own global x, y (`same_pairs_in_global_frame`: the shared placement error kept); `true_label` maps
    (M, 2) true global x, y to the true class there, `Semantic.UNOBSERVED` where the truth is not scored. None for
    a class neither side holds."""
    labels = np.asarray(labels)
    if labels.shape != (len(points_xyz),):
        raise ValueError(f"labels: expected one per point ({len(points_xyz)}), got shape {labels.shape}")
    points = _checked_points(points_xyz)
    in_place = true_label(points[:, :2])
    counts = {frame: _ClassCounts(classes) for frame in ("ego", "same_pairs_in_global_frame")}
    for pairs in ego_pairs(points, world_from_ego, true_world_from_ego, box):
        ours = labels[pairs.index]
        counts["ego"].add(ours, true_label(pairs.true_world_xyz[:, :2]))
        counts["same_pairs_in_global_frame"].add(ours, in_place[pairs.index])
    return {frame: count.iou() for frame, count in counts.items()}


class _ClassCounts:
    """Intersections and unions per named class, over the pairs where the truth is scored."""

    def __init__(self, classes: Mapping[str, int]) -> None:
        self.classes = dict(classes)
        self.intersection = dict.fromkeys(classes, 0)
        self.union = dict.fromkeys(classes, 0)

    def add(self, ours: np.ndarray, truth: np.ndarray) -> None:
        scored = truth != int(Semantic.UNOBSERVED)
        ours, truth = ours[scored], truth[scored]
        for name, cls in self.classes.items():
            self.intersection[name] += int(((ours == cls) & (truth == cls)).sum())
            self.union[name] += int(((ours == cls) | (truth == cls)).sum())

    def iou(self) -> dict[str, float | None]:
        return {
            name: self.intersection[name] / self.union[name] if self.union[name] else None
            for name in self.classes
        }
