"""Sequential pairs within a clip: each camera with itself a few keyframes later, and rig cameras whose views
overlap within the same and neighbouring keyframes."""

from collections import defaultdict
from itertools import combinations

import numpy as np

from cama_pipeline.cameras import CameraView
from cama_pipeline.pairs.config import PairsConfig

Pair = tuple[int, int]
"""Indices into the view list, smaller first."""


def ordered(i: int, j: int) -> Pair:
    """The pair with the smaller index first."""
    return (i, j) if i < j else (j, i)


def overlapping_channels(views: list[CameraView], max_axis_angle_deg: float) -> set[frozenset[str]]:
    """Channel pairs whose optical axes (in the ego frame, from the extrinsics) are close enough to overlap."""
    axes: dict[str, np.ndarray] = {}
    for view in views:
        axes.setdefault(view.channel, view.ego_from_cam[:3, 2])
    cos_limit = np.cos(np.radians(max_axis_angle_deg))
    return {
        frozenset((a, b))
        for a, b in combinations(sorted(axes), 2)
        if float(np.dot(axes[a], axes[b])) >= cos_limit
    }


def sequential_pairs(views: list[CameraView], config: PairsConfig) -> dict[Pair, str]:
    """`temporal` pairs (same camera, up to `sequential_window` keyframes apart) and `rig` pairs (overlapping
    cameras, up to `rig_window` keyframes apart), within each scene."""
    by_frame: dict[tuple[str, int], list[int]] = defaultdict(list)
    for index, view in enumerate(views):
        by_frame[(view.scene, view.frame_index)].append(index)
    rig = overlapping_channels(views, config.rig_max_axis_angle_deg)
    pairs: dict[Pair, str] = {}
    for (scene, frame), members in by_frame.items():
        reach = max(config.sequential_window, config.rig_window)
        for offset in range(reach + 1):
            for i in members:
                for j in by_frame.get((scene, frame + offset), []):
                    if i == j:
                        continue
                    same = views[i].channel == views[j].channel
                    if same and 0 < offset <= config.sequential_window:
                        pairs.setdefault(ordered(i, j), "temporal")
                    elif not same and offset <= config.rig_window:
                        if frozenset((views[i].channel, views[j].channel)) in rig:
                            pairs.setdefault(ordered(i, j), "rig")
    return pairs
