"""The merge on real clips of the tiny site (two drives through one intersection): a clip moved by a known
similarity is brought back by the alignment from their shared points."""

from pathlib import Path

import numpy as np
import pycolmap
import pytest

from cama_pipeline.sfm.config import SfmConfig
from cama_pipeline.sfm.guided import reconstruct_views, refined_views
from cama_pipeline.sfm.height_ties import alignment_priors, heights_before_alignment, tie_heights
from cama_pipeline.sfm.merge import ClipModel, MergeConfig, align_clips, aligned_views, cross_clip_matches
from cama_pipeline.sfm.stage import site_clips
from cama_pipeline.site.io import read_site_manifest
from cama_pipeline.workspace import Workspace

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def clips(sfm_inputs: object) -> list[ClipModel]:
    """Each clip of the site reconstructed on its own (rigid BA)."""
    inputs = sfm_inputs
    manifest = read_site_manifest(Workspace(inputs.workspace).site_manifest(inputs.site_id))  # type: ignore[attr-defined]
    models = []
    for scene, views in site_clips(list(inputs.views), manifest).items():  # type: ignore[attr-defined]
        result = reconstruct_views(views, inputs.database, inputs.image_dir, SfmConfig.preset("rigid"))  # type: ignore[attr-defined]
        models.append(ClipModel(scene, result.reconstruction, tuple(refined_views(result, views))))
    assert len(models) == 2
    return models


def offset_clip(clip: ClipModel, world_from_clip: np.ndarray) -> ClipModel:
    """A copy of the clip moved by a similarity: its points, cameras and views."""
    model = pycolmap.Reconstruction(clip.reconstruction)
    model.transform(pycolmap.Sim3d(world_from_clip[:3, :]))
    return ClipModel(clip.scene, model, tuple(aligned_views(clip.views, world_from_clip)))


def known_offset(centre: np.ndarray) -> np.ndarray:
    """1.5 deg about z and 1 % scale about the clip's centre, then 1.2 m sideways and 0.3 m up."""
    angle = np.radians(1.5)
    offset = np.eye(4)
    offset[:3, :3] = 1.01 * np.array(
        [[np.cos(angle), -np.sin(angle), 0], [np.sin(angle), np.cos(angle), 0], [0, 0, 1]]
    )
    offset[:3, 3] = centre + np.array([0.0, 1.2, 0.3]) - offset[:3, :3] @ centre
    return offset


def relative(alignments: list) -> np.ndarray:  # type: ignore[type-arg]
    """world_from_clip of the second clip relative to the first's."""
    return np.linalg.inv(alignments[0].world_from_clip) @ alignments[1].world_from_clip


def test_merge_brings_back_a_clip_moved_by_a_known_similarity(
    sfm_inputs: object, clips: list[ClipModel]
) -> None:
    matches = cross_clip_matches(Path(sfm_inputs.database))  # type: ignore[attr-defined]
    natural = align_clips(clips, matches, MergeConfig())
    assert natural[1].method == "points" or natural[0].method == "points"
    centre = np.mean([v.center for v in clips[1].views], axis=0)
    offset = known_offset(centre)
    moved = align_clips([clips[0], offset_clip(clips[1], offset)], matches, MergeConfig())
    assert {a.method for a in moved} == {"points", "poses"} and max(a.correspondences for a in moved) >= 20
    # Aligned, the moved clip lands where the unmoved one did: relative alignment = natural one undoing the offset.
    expected = relative(natural) @ np.linalg.inv(offset)
    found = relative(moved)
    cameras = np.array([v.center for v in clips[1].views])
    moved_cameras = cameras @ offset[:3, :3].T + offset[:3, 3]
    placed = moved_cameras @ found[:3, :3].T + found[:3, 3]
    wanted = moved_cameras @ expected[:3, :3].T + expected[:3, 3]
    assert np.abs(placed - wanted).max() < 0.05  # metres
    # and it took a real correction: the offset alone moves the cameras by over a metre
    assert np.linalg.norm(moved_cameras - cameras, axis=1).min() > 1.0


def test_unjoined_clips_with_free_heights_meet_on_the_road(
    sfm_inputs: object, clips: list[ClipModel]
) -> None:
    """The second drive lifted 2.5 m (WIGO's gauge with 2D logged poses) and no point allowed to join the two
    (`min_correspondences` out of reach): tied by the ego heights of the opposite carriageway, 7.3 m across, the
    lifted drive comes back to within 10 cm of where the points put it (5.7 cm here: the road's cross-fall)."""
    matches = cross_clip_matches(Path(sfm_inputs.database))  # type: ignore[attr-defined]
    natural = align_clips(clips, matches, MergeConfig())
    lift = np.eye(4)
    lift[2, 3] = 2.5
    lifted = [clips[0], offset_clip(clips[1], lift)]
    unjoined = align_clips(lifted, matches, MergeConfig(min_correspondences=10**9))
    assert {a.method for a in unjoined} == {"poses"}
    scenes = {clip.scene for clip in clips}
    config = MergeConfig()
    tied, ties = tie_heights(
        lifted, unjoined, scenes, radius_m=config.height_tie_radius_m, min_pairs=config.height_tie_min_pairs
    )
    assert len(ties) == 1 and next(iter(ties.values())).tied
    centre = np.mean([v.center for v in clips[1].views], axis=0)
    natural_z = (relative(natural) @ np.append(centre, 1.0))[2]
    tied_z = (relative(tied) @ lift @ np.append(centre, 1.0))[2]
    assert abs(tied_z - natural_z) < 0.1
    assert abs((relative(unjoined) @ lift @ np.append(centre, 1.0))[2] - natural_z) > 2.0


def test_a_free_clip_metres_too_high_is_tied_then_aligned_by_its_points(
    sfm_inputs: object, clips: list[ClipModel]
) -> None:
    """The second drive lifted 8 m, beyond the similarity's `max_shift_m` (5 m): aligned as it stands, its
    points are refused and it keeps its height; tied first (`heights_before_alignment`), its points align it to
    within 2 cm of where they put the unlifted drive. Had its height been measured, the other drive would have
    risen to it instead."""
    matches = cross_clip_matches(Path(sfm_inputs.database))  # type: ignore[attr-defined]
    natural = align_clips(clips, matches, MergeConfig())
    lift = np.eye(4)
    lift[2, 3] = 8.0
    lifted = [clips[0], offset_clip(clips[1], lift)]
    config = MergeConfig()
    untied = align_clips(lifted, matches, config)
    assert [a.method for a in untied] == ["poses", "poses"]
    scenes = {clip.scene for clip in clips}
    priors, ties = heights_before_alignment(
        lifted, scenes, radius_m=config.height_tie_radius_m, min_pairs=config.height_tie_min_pairs
    )
    assert sum(tie.tied for tie in ties.values()) == 1
    aligned = align_clips(lifted, matches, config, priors)
    assert sorted(a.method for a in aligned) == ["points", "poses"]
    centre = np.mean([v.center for v in clips[1].views], axis=0)
    natural_z = (relative(natural) @ np.append(centre, 1.0))[2]
    assert abs((relative(aligned) @ lift @ np.append(centre, 1.0))[2] - natural_z) < 0.02
    measured, _ = heights_before_alignment(
        lifted, {clips[0].scene}, radius_m=config.height_tie_radius_m, min_pairs=config.height_tie_min_pairs
    )
    assert np.array_equal(measured[1], np.eye(4))  # the lifted drive's height was measured: it stays
    assert measured[0][2, 3] == pytest.approx(8.0, abs=0.1)  # and the free one rises to meet it


def test_the_tie_before_the_alignment_can_be_switched_off(clips: list[ClipModel]) -> None:
    """`height_ties_before_alignment` (on by default) gives the tie's priors; off, or with no free-height clip,
    `align_clips` judges every clip where WIGO left it (the ablation of the logged-height table's hilly rows)."""
    lift = np.eye(4)
    lift[2, 3] = 8.0
    lifted = [clips[0], offset_clip(clips[1], lift)]
    scenes = {clip.scene for clip in clips}
    priors, ties = alignment_priors(lifted, scenes, MergeConfig())
    assert priors is not None and sum(tie.tied for tie in ties.values()) == 1
    assert abs(priors[0][2, 3] - priors[1][2, 3]) == pytest.approx(8.0, abs=0.1)
    assert alignment_priors(lifted, scenes, MergeConfig(height_ties_before_alignment=False)) == (None, {})
    assert alignment_priors(lifted, (), MergeConfig()) == (None, {})


def test_a_wrong_prior_does_not_cost_a_clip_its_points(sfm_inputs: object, clips: list[ClipModel]) -> None:
    """A prior 8 m off (a height tied to the road under a bridge, say): the points are refused from there, and
    judged again from where the clip stands they align it as without the prior."""
    matches = cross_clip_matches(Path(sfm_inputs.database))  # type: ignore[attr-defined]
    natural = align_clips(clips, matches, MergeConfig())
    wrong = np.eye(4)
    wrong[2, 3] = 8.0
    priors = [np.eye(4), wrong] if natural[1].method == "points" else [wrong, np.eye(4)]
    aligned = align_clips(clips, matches, MergeConfig(), priors)
    assert [a.method for a in aligned] == [a.method for a in natural]
    for ours, theirs in zip(aligned, natural, strict=True):  # the group is placed as without the prior, too
        np.testing.assert_allclose(ours.world_from_clip, theirs.world_from_clip, atol=1e-6)
