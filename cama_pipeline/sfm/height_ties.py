"""The merge's use of `cama_pipeline.site.heights`: clips whose heights nothing measured (2D logged poses, no
GNSS) are moved to the height of the road the other clips drove, twice:

- before the point alignment (`heights_before_alignment`), each clip on its own: WIGO leaves such a clip at its
  first pose's logged height, metres from the others' on a hilly site, and the alignment's plausibility check
  (`MergeConfig.max_shift_m`) would refuse a similarity that has to move it that far; tied first, the points
  only have to correct the tie's own error (the road's cross-fall, centimetres);
- after it (`tie_heights`), the groups no point joins, as groups.

The merged BA keeps the moves: its absolute priors are the aligned poses."""

from collections.abc import Collection, Sequence
from dataclasses import replace

import numpy as np

from cama_pipeline.sfm.merge import Alignment, ClipModel, MergeConfig, merge_groups
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


def heights_before_alignment(
    clips: Sequence[ClipModel], free_height: Collection[str], *, radius_m: float, min_pairs: int
) -> tuple[list[np.ndarray], dict[str, HeightTie]]:
    """Per clip (clip order) the vertical move (4x4 world_from_clip) that ties its height to the clips placed
    before it, each clip on its own (no alignment yet), and the ties of the free-height scenes."""
    unaligned = [Alignment(clip.scene, None, "poses", 0, np.eye(4)) for clip in clips]
    tied, ties = tie_heights(clips, unaligned, free_height, radius_m=radius_m, min_pairs=min_pairs)
    return [alignment.world_from_clip for alignment in tied], ties


def alignment_priors(
    clips: Sequence[ClipModel], free_height: Collection[str], config: MergeConfig
) -> tuple[list[np.ndarray] | None, dict[str, HeightTie]]:
    """Where `align_clips` judges each clip from (clip order), and the ties that put it there: the free-height
    clips tied first (`heights_before_alignment`) when `config.height_ties_before_alignment`; None (each clip
    where WIGO left it) and no ties when that is off or no clip's height is free."""
    if not (config.height_ties_before_alignment and free_height):
        return None, {}
    return heights_before_alignment(
        clips, free_height, radius_m=config.height_tie_radius_m, min_pairs=config.height_tie_min_pairs
    )
