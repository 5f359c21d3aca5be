"""Relative heights of a site's clips where nothing measured them: each free-height clip tied to the road the
other clips drove.

Why: a data set whose logged ego poses carry no height (nuScenes' localization is 2D: every z is 0) and that has no
GNSS leaves each clip's height where WIGO's gauge put it, near the height of its first pose's log, so two clips of
one site may start metres apart in height (2.7 m on the default synthetic site; more in a hilly city). Two stages
read heights across clips before SfM can join them: the pairs stage's height rule (`PairsConfig.max_dz_m`, 3 m)
would drop every spatial pair between such clips, and SfM's merge joins only clips that share points, so a clip
that shares none would keep WIGO's offset and the surface stage would see one road at two heights.

How: every clip of a site overlaps another within the sites stage's radius, and the ego frame stands at the same
height above the road in every clip of one vehicle. So where a free-height group's keyframes pass within
`radius_m` (horizontally) of a placed group's track, and the placed group's keyframes within it of the free group's
track, the median difference of the heights (the track's interpolated along its segment) is the group's vertical
offset. Placed first: the groups with a clip whose height is measured (fused logged heights, GNSS), else the
largest group; then the free groups in order of most pairs. A free group near no placed one keeps its height, and
says so. A track is taken as level across itself: a crowned road stands at one height at equal distances either
side of its crown (opposite lanes), while a one-sided cross-fall of 2 % over the 7 m to the opposite carriageway
is 14 cm, small against the metres the tie removes.
"""

import logging
from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from cama_pipeline.cameras import CameraView

logger = logging.getLogger(__name__)

TIE_RADIUS_M = 8.0
"""A keyframe this close (horizontally) to another clip's track is taken to stand on the same road: the opposite
carriageway of a four-lane road is about 7 m away (the tiny synthetic site's two drives: 7.3 m)."""
TIE_MIN_PAIRS = 2
"""Keyframes near the other group's track needed to tie a group's height (two drives that cross meet at one or
two keyframes each)."""


@dataclass(frozen=True)
class HeightTie:
    """The vertical move of one group of clips and what it rests on."""

    offset_m: float
    """Metres added to the group's heights (0 when it could not be tied)."""
    pairs: int
    """Keyframes of the group within the radius of a placed group's track, and of a placed group's within the
    radius of the group's track."""
    tied: bool

    def to_json(self) -> dict[str, Any]:
        return {"offset_m": self.offset_m, "pairs": self.pairs, "tied": self.tied}


def keyframe_track(views: Sequence[CameraView], world_from_clip: np.ndarray | None = None) -> np.ndarray:
    """(F, 3) one ego position per keyframe (its first view's), in frame order, moved by `world_from_clip`."""
    first: dict[int, np.ndarray] = {}
    for view in views:
        first.setdefault(view.frame_index, view.world_from_ego[:3, 3])
    own = np.array([first[k] for k in sorted(first)]).reshape(-1, 3)
    if world_from_clip is None:
        return own
    return np.asarray(own @ world_from_clip[:3, :3].T + world_from_clip[:3, 3])


def heights_on_tracks(points: np.ndarray, tracks: Sequence[np.ndarray], radius_m: float) -> np.ndarray:
    """(N,) the height of the nearest track (interpolated along its segment) under each point, NaN where no
    track passes within `radius_m` horizontally. Tracks, not their keyframes, since two drives that cross may
    have no keyframes within metres of each other."""
    best = np.full(len(points), np.inf)
    height = np.full(len(points), np.nan)
    for track in tracks:
        starts, ends = (track[:-1], track[1:]) if len(track) > 1 else (track, track)
        along = ends[:, :2] - starts[:, :2]
        length2 = np.maximum((along**2).sum(axis=1), 1e-12)
        offset = points[:, None, :2] - starts[None, :, :2]
        t = np.clip((offset * along[None]).sum(axis=2) / length2[None], 0.0, 1.0)
        foot = starts[None, :, :2] + t[..., None] * along[None]
        distance = np.linalg.norm(points[:, None, :2] - foot, axis=2)
        nearest = distance.argmin(axis=1)
        rows = np.arange(len(points))
        closer = distance[rows, nearest] < best
        z = starts[nearest, 2] + t[rows, nearest] * (ends[nearest, 2] - starts[nearest, 2])
        best = np.where(closer, distance[rows, nearest], best)
        height = np.where(closer, z, height)
    return np.where(best <= radius_m, height, np.nan)


def height_differences(
    free: Sequence[np.ndarray], placed: Sequence[np.ndarray], radius_m: float
) -> np.ndarray:
    """Placed minus free height wherever a free keyframe lies within `radius_m` of a placed track, and wherever a
    placed keyframe lies within it of a free track."""
    if not free or not placed:
        return np.zeros(0)
    free_points, placed_points = np.concatenate(free), np.concatenate(placed)
    on_placed = heights_on_tracks(free_points, placed, radius_m) - free_points[:, 2]
    under_placed = placed_points[:, 2] - heights_on_tracks(placed_points, free, radius_m)
    both = np.concatenate([on_placed, under_placed])
    return both[np.isfinite(both)]


def level_groups(
    groups: Sequence[Sequence[str]],
    tracks: Mapping[str, np.ndarray],
    free_height: Collection[str],
    *,
    radius_m: float = TIE_RADIUS_M,
    min_pairs: int = TIE_MIN_PAIRS,
) -> dict[str, HeightTie]:
    """The tie of every scene of the groups whose scenes all have free heights (module docstring); `groups`:
    scenes whose relative heights are already known (joined by points, or each scene alone), `tracks`: each
    scene's `keyframe_track`."""
    free_groups: list[list[str]] = []
    placed: list[list[str]] = []
    for g in groups:
        (free_groups if all(scene in free_height for scene in g) else placed).append(list(g))
    if not placed and free_groups:  # nothing measured: the largest group sets the height
        largest = max(free_groups, key=lambda g: sum(len(tracks[s]) for s in g))
        free_groups.remove(largest)
        placed.append(largest)
    placed_tracks = [tracks[s] for g in placed for s in g]
    ties: dict[str, HeightTie] = {}
    while free_groups:
        found = {
            tuple(g): height_differences([tracks[s] for s in g], placed_tracks, radius_m) for g in free_groups
        }
        group = max(free_groups, key=lambda g: len(found[tuple(g)]))
        differences = found[tuple(group)]
        if len(differences) < min_pairs:
            for g in free_groups:
                for scene in g:
                    ties[scene] = HeightTie(0.0, len(found[tuple(g)]), tied=False)
            logger.warning(
                "clips %s: free heights and no placed clip within %.1f m: they keep WIGO's heights",
                [s for g in free_groups for s in g],
                radius_m,
            )
            break
        offset = float(np.median(differences))
        for scene in group:
            ties[scene] = HeightTie(offset, len(differences), tied=True)
        logger.info(
            "clips %s: heights tied to the placed clips, %+.3f m (%d pairs)", group, offset, len(differences)
        )
        placed_tracks += [tracks[s] + np.array([0.0, 0.0, offset]) for s in group]
        free_groups.remove(group)
    return ties
