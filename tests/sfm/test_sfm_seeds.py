"""The merge started from its clips' refined points (seeds) instead of a triangulation from scratch: tracks
join across clips, observations of images outside the model are dropped, and the poses are as good."""

import numpy as np
import pytest

from cama_pipeline.cameras import CameraView
from cama_pipeline.sfm.config import SfmConfig
from cama_pipeline.sfm.guided import GuidedResult, reconstruct_views
from cama_pipeline.sfm.stage import site_clips
from cama_pipeline.sfm.triangulate import SeedPoints, model_seeds
from cama_pipeline.site.io import read_site_manifest
from cama_pipeline.workspace import Workspace

pytestmark = pytest.mark.slow
MERGE = SfmConfig.preset("iterative", max_iterations=1)


@pytest.fixture(scope="module")
def clips(sfm_inputs: object) -> dict[str, tuple[list[CameraView], GuidedResult]]:
    """Each clip of the tiny site reconstructed on its own (Algorithm 1), by scene."""
    inputs = sfm_inputs
    manifest = read_site_manifest(Workspace(inputs.workspace).site_manifest(inputs.site_id))  # type: ignore[attr-defined]
    return {
        scene: (views, reconstruct_views(views, inputs.database, inputs.image_dir, SfmConfig()))  # type: ignore[attr-defined]
        for scene, views in site_clips(list(inputs.views), manifest).items()  # type: ignore[attr-defined]
    }


def _merged(sfm_inputs: object, clips: dict, seeds: list[SeedPoints]) -> GuidedResult:  # type: ignore[type-arg]
    union = [view for views, _ in clips.values() for view in views]
    return reconstruct_views(union, sfm_inputs.database, sfm_inputs.image_dir, MERGE, seeds=seeds)  # type: ignore[attr-defined]


def _position_error_cm(result: GuidedResult, truth: dict[str, np.ndarray]) -> float:
    return float(
        np.mean(
            [np.linalg.norm(pose[:3, 3] - truth[name][:3, 3]) for name, pose in result.world_from_ego.items()]
        )
        * 100
    )


def test_seeded_merge_joins_clips_and_matches_a_fresh_triangulation(sfm_inputs: object, clips: dict) -> None:  # type: ignore[type-arg]
    seeds = [model_seeds(result.reconstruction, np.eye(4)) for _, result in clips.values()]
    seeded = _merged(sfm_inputs, clips, seeds)
    fresh = _merged(sfm_inputs, clips, [])
    truth = sfm_inputs.true_world_from_ego  # type: ignore[attr-defined]
    assert seeded.report["registered_images"] == fresh.report["registered_images"]
    assert _position_error_cm(seeded, truth) <= _position_error_cm(fresh, truth) + 1.0
    assert seeded.report["points"] >= 0.8 * fresh.report["points"]
    clip_of = {view.name: scene for scene, (views, _) in clips.items() for view in views}
    spanning = sum(
        len({clip_of[seeded.reconstruction.image(e.image_id).name] for e in point.track.elements}) > 1
        for point in seeded.reconstruction.points3D.values()
    )
    assert spanning >= 20  # tracks were completed and merged across the clips


def test_seeds_outside_the_model_are_dropped(sfm_inputs: object, clips: dict) -> None:  # type: ignore[type-arg]
    (views, result), *_ = clips.values()
    seed = model_seeds(result.reconstruction, np.eye(4))
    kept = views[: len(views) // 2]
    kept_ids = {result.reconstruction.find_image_with_name(v.name).image_id for v in kept}  # type: ignore[union-attr]
    seeded = reconstruct_views(kept, sfm_inputs.database, sfm_inputs.image_dir, MERGE, seeds=[seed])  # type: ignore[attr-defined]
    observed = {e.image_id for p in seeded.reconstruction.points3D.values() for e in p.track.elements}
    assert observed <= kept_ids


def test_model_seeds_are_moved_by_the_similarity(clips: dict) -> None:  # type: ignore[type-arg]
    _, result = next(iter(clips.values()))
    similarity = np.diag([1.01, 1.01, 1.01, 1.0])
    similarity[:3, 3] = [1.0, -2.0, 0.5]
    still, moved = (
        model_seeds(result.reconstruction, np.eye(4)),
        model_seeds(result.reconstruction, similarity),
    )
    assert np.allclose(moved.xyz, 1.01 * still.xyz + [1.0, -2.0, 0.5])
    assert len(moved.tracks) == len(moved.xyz) == len(moved.colors) == result.reconstruction.num_points3D()
