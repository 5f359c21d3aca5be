"""The merge's use of `cama_pipeline.site.heights`: clips no point joins and whose heights nothing measured
(2D logged poses, no GNSS) are moved, before the merged BA, to the height of the road the other clips drove. The
merged BA keeps the move: its absolute priors are the aligned poses."""

from collections.abc import Collection, Sequence
from dataclasses import replace

import numpy as np

from cama_pipeline.sfm.merge import Alignment, ClipModel, merge_groups
from cama_pipeline.site.heights import HeightTie, keyframe_track, level_groups


def tie_heights(
    clips: Sequence[ClipModel],
    alignments: Sequence[Alignment],
    free_height: Collection[str],
    *,
    radius_m: float,
    min_pairs: int,
) -> tuple[list[Alignment], dict[str, HeightTie]]:
    """`alignments` (clip order) with each free-height group's vertical offset applied, and the tie of every
    scene of those groups. `free_height`: the scenes whose heights nothing measured."""
    tracks = {
        clip.scene: keyframe_track(clip.views, alignment.world_from_clip)
        for clip, alignment in zip(clips, alignments, strict=True)
    }
    ties = level_groups(merge_groups(alignments), tracks, free_height, radius_m=radius_m, min_pairs=min_pairs)
    moved = []
    for alignment in alignments:
        lift = np.eye(4)
        lift[2, 3] = ties[alignment.scene].offset_m if alignment.scene in ties else 0.0
        moved.append(replace(alignment, world_from_clip=lift @ alignment.world_from_clip))
    return moved, ties
