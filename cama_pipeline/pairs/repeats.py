"""Repeated views: keyframe images that show what an earlier image of the same camera already showed, from the
same place (a stationary clip keeps every frame, so one camera sees one view a hundred times).

Pairing every repeat spatially with everything around it multiplies the matching and the SfM work for no new
geometry (default site: 57 % of the pairs touched its stationary clip). A repeat is paired with the image it
repeats (its representative) and keeps its temporal and rig pairs; only representatives get spatial pairs.
"""

from collections import defaultdict

import numpy as np

from cama_pipeline.cameras import CameraView
from cama_pipeline.pairs.config import PairsConfig
from cama_pipeline.pairs.sequential import Pair, ordered


def repeated_views(views: list[CameraView], config: PairsConfig) -> dict[int, int]:
    """Index of each repeated view -> index of the view it repeats: the first earlier image (keyframe order)
    of the same scene and camera whose centre is within `repeat_distance_m` and optical axis within
    `repeat_angle_deg`. Empty when `repeat_distance_m` is 0."""
    if config.repeat_distance_m == 0:
        return {}
    by_camera: dict[tuple[str, str], list[int]] = defaultdict(list)
    for index in sorted(range(len(views)), key=lambda i: views[i].frame_index):
        by_camera[(views[index].scene, views[index].channel)].append(index)
    cos_limit = np.cos(np.radians(config.repeat_angle_deg))
    repeats: dict[int, int] = {}
    for members in by_camera.values():
        representatives: list[int] = []
        for index in members:
            view = views[index]
            same = next(
                (
                    r
                    for r in representatives
                    if np.linalg.norm(views[r].center - view.center) <= config.repeat_distance_m
                    and float(np.dot(views[r].axis, view.axis)) >= cos_limit
                ),
                None,
            )
            if same is None:
                representatives.append(index)
            else:
                repeats[index] = same
    return repeats


def repeat_pairs(repeats: dict[int, int]) -> dict[Pair, str]:
    """Each repeat with its representative (their features chain every repeat into the representative's tracks)."""
    return {ordered(index, representative): "repeat" for index, representative in repeats.items()}
