"""Executors: the local process pool and Ray run the same task function and give the same results."""

import os
from pathlib import Path

import numpy as np
import pytest

from cama_pipeline.sfm.config import SfmConfig
from cama_pipeline.sfm.executor import LocalExecutor, RayExecutor, make_executor
from cama_pipeline.sfm.stage import ClipTask, reconstruct_clip
from tests.dependency_policy import require_module


def test_local_pool_returns_results_in_task_order_and_reports_each() -> None:
    done: list[int] = []
    paths = ["/a/first", "/b/second", "/c/third"]
    assert LocalExecutor(2).map(os.path.basename, paths, on_done=done.append) == ["first", "second", "third"]
    assert sorted(done) == [0, 1, 2]
    assert LocalExecutor(1).map(os.path.basename, []) == []


def test_unknown_executor_or_no_workers_is_refused() -> None:
    with pytest.raises(ValueError, match="executor must be one of"):
        make_executor("slurm")
    with pytest.raises(ValueError, match="workers must be >= 1"):
        make_executor("ray", workers=0)


@pytest.fixture(scope="module")
def local_ray() -> object:
    """One small local Ray instance for the module (start-up takes 10-20 s)."""
    ray = require_module("ray")
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    yield ray
    ray.shutdown()


@pytest.mark.slow
def test_ray_and_local_reconstruct_a_clip_identically(
    sfm_inputs: object, local_ray: object, tmp_path: Path
) -> None:
    inputs = sfm_inputs
    scene = min(inputs.scenes, key=lambda s: len(inputs.scene_views(s)))  # type: ignore[attr-defined]
    views = tuple(inputs.scene_views(scene))  # type: ignore[attr-defined]

    def task(folder: str) -> ClipTask:
        return ClipTask(
            scene, views, inputs.database, inputs.image_dir, SfmConfig.preset("rigid"), tmp_path / folder
        )  # type: ignore[attr-defined]

    (local,) = LocalExecutor(1).map(reconstruct_clip, [task("local")])
    (remote,) = RayExecutor(1).map(reconstruct_clip, [task("ray")])
    assert local.ok and remote.ok, (local.error, remote.error)
    assert local.report["registered_images"] == remote.report["registered_images"] > 0
    assert local.report["points"] == remote.report["points"]
    for a, b in zip(local.views, remote.views, strict=True):
        np.testing.assert_allclose(a.world_from_ego, b.world_from_ego, atol=1e-9)
    assert (tmp_path / "local" / "images.bin").read_bytes() == (tmp_path / "ray" / "images.bin").read_bytes()
