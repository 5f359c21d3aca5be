"""Heights of clips the merge could not join by points, when nothing else gives them: tied to the road the other
clips drove.

Why: a data set whose logged ego poses carry no height (nuScenes' localization is 2D: every z is 0) and that has
no GNSS leaves each clip's height where WIGO's gauge put it, near the height of its first pose's log, so two clips
of one site may start metres apart in height (2.7 m on the default synthetic site). The merge joins clips that
share SfM points, and a joined clip takes its height from them; a clip that shares none ("poses" alignment)
would keep WIGO's offset, and the surface stage would then see one road at two heights.

How: every clip of a site overlaps another within the sites stage's radius, and the ego frame stands at the same
height above the road in every clip of one vehicle. So where a free-height group's keyframes pass within
`MergeConfig.height_tie_radius_m` (horizontally) of a placed group's track, and the placed group's keyframes within
it of the free group's track, the median difference of the heights (the track's interpolated along its segment) is
the group's vertical offset, applied to its alignments before the merged BA (which keeps it: the BA's absolute
priors are the aligned poses). Placed first: the groups with a clip whose height is measured (fused logged
heights, GNSS), else the largest group; then the free groups in order of most pairs. A free group near no placed
one keeps its height, and the report says so. A track is taken as level across itself: a crowned road stands
at one height at equal distances either side of its crown (opposite lanes), while a one-sided cross-fall of 2 %
over the 7 m to the opposite carriageway is 14 cm, small against the metres the tie removes.
"""

import logging
from collections.abc import Collection, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from cama_pipeline.sfm.merge import Alignment, ClipModel, merge_groups

logger = logging.getLogger(__name__)


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


def _track(clip: ClipModel, alignment: Alignment) -> np.ndarray:
    """(F, 3) the clip's ego positions in the merged frame, one per keyframe (its first view), in frame order."""
    first: dict[int, np.ndarray] = {}
    for view in clip.views:
        first.setdefault(view.frame_index, view.world_from_ego[:3, 3])
    own = np.array([first[k] for k in sorted(first)]).reshape(-1, 3)
    similarity = alignment.world_from_clip
    return np.asarray(own @ similarity[:3, :3].T + similarity[:3, 3])


def _heights_on_tracks(points: np.ndarray, tracks: Sequence[np.ndarray], radius_m: float) -> np.ndarray:
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


def _height_differences(
    free: Sequence[np.ndarray], placed: Sequence[np.ndarray], radius_m: float
) -> np.ndarray:
    """Placed minus free height wherever a free keyframe lies within `radius_m` of a placed track, and wherever a
    placed keyframe lies within it of a free track."""
    if not free or not placed:
        return np.zeros(0)
    free_points, placed_points = np.concatenate(free), np.concatenate(placed)
    on_placed = _heights_on_tracks(free_points, placed, radius_m) - free_points[:, 2]
    under_placed = placed_points[:, 2] - _heights_on_tracks(placed_points, free, radius_m)
    both = np.concatenate([on_placed, under_placed])
    return both[np.isfinite(both)]


def tie_heights(
    clips: Sequence[ClipModel],
    alignments: Sequence[Alignment],
    free_height: Collection[str],
    *,
    radius_m: float,
    min_pairs: int,
) -> tuple[list[Alignment], dict[str, HeightTie]]:
    """`alignments` (clip order) with each free-height group's vertical offset applied (module docstring), and
    the tie of every free group by the scenes it holds. `free_height`: the scenes whose heights nothing measured."""
    by_scene = {clip.scene: (clip, alignment) for clip, alignment in zip(clips, alignments, strict=True)}
    tracks = {scene: _track(clip, alignment) for scene, (clip, alignment) in by_scene.items()}
    groups = merge_groups(alignments)
    free_groups = [g for g in groups if all(scene in free_height for scene in g)]
    placed = [g for g in groups if g not in free_groups]
    if not placed and free_groups:  # nothing measured: the largest group sets the height
        largest = max(free_groups, key=lambda g: sum(len(by_scene[s][0].views) for s in g))
        free_groups.remove(largest)
        placed.append(largest)
    placed_tracks = [tracks[s] for g in placed for s in g]
    offsets: dict[str, float] = {}
    ties: dict[str, HeightTie] = {}
    while free_groups:
        found = {
            tuple(g): _height_differences([tracks[s] for s in g], placed_tracks, radius_m)
            for g in free_groups
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
            offsets[scene] = offset
            ties[scene] = HeightTie(offset, len(differences), tied=True)
            tracks[scene] = tracks[scene] + np.array([0.0, 0.0, offset])
        logger.info(
            "clips %s: heights tied to the placed clips, %+.3f m (%d pairs)", group, offset, len(differences)
        )
        placed_tracks += [tracks[s] for s in group]
        free_groups.remove(group)
    moved = []
    for alignment in alignments:
        offset = offsets.get(alignment.scene, 0.0)
        lift = np.eye(4)
        lift[2, 3] = offset
        moved.append(replace(alignment, world_from_clip=lift @ alignment.world_from_clip))
    return moved, ties
