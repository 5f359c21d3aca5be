"""A location-disjoint train/validation split of a data set's scenes (as the paper repartitions nuScenes).

Scenes whose trajectories come within `overlap_m` of each other see the same places, so they are grouped
(transitively, union-find) and every group lands wholly on one side; groups are drawn in a seeded random
order into validation until it holds about `val_share` of the scenes. Reported AP is then not inflated by
places the model memorised in training.
"""

import logging
from collections.abc import Mapping
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from cama_pipeline.data import load_dataset
from cama_pipeline.io import atomic_write_json

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class SplitConfig:
    """How scenes are grouped and split."""

    val_share: float = 0.25
    """Target share of scenes in validation."""
    overlap_m: float = 50.0
    """Scenes whose trajectories pass within this distance share a location (BEV maps reach ~30 m out)."""
    seed: int = 0

    def __post_init__(self) -> None:
        if not 0.0 < self.val_share < 1.0:
            raise ValueError(f"SplitConfig.val_share must be in (0, 1), got {self.val_share}")
        if not self.overlap_m > 0:
            raise ValueError(f"SplitConfig.overlap_m must be > 0, got {self.overlap_m}")


@dataclass(frozen=True)
class Split:
    """Scene names on each side and the location groups they came from."""

    train: list[str]
    val: list[str]
    groups: list[list[str]]


def location_groups(trajectories: Mapping[str, np.ndarray], overlap_m: float) -> list[list[str]]:
    """Scenes grouped transitively by trajectories passing within `overlap_m` of each other."""
    names = sorted(trajectories)
    parent = list(range(len(names)))

    def root(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    trees = [cKDTree(np.asarray(trajectories[n], dtype=float)[:, :2]) for n in names]
    for i in range(len(names)):
        for j in range(i + 1, len(names)):
            if root(i) != root(j) and trees[i].count_neighbors(trees[j], overlap_m) > 0:
                parent[root(j)] = root(i)
    groups: dict[int, list[str]] = {}
    for i, name in enumerate(names):
        groups.setdefault(root(i), []).append(name)
    return sorted(groups.values())


def split_scenes(trajectories: Mapping[str, np.ndarray], config: SplitConfig | None = None) -> Split:
    """A location-disjoint split of scenes given as name -> (N, 2+) trajectory points in global metres."""
    config = config or SplitConfig()
    if len(trajectories) < 2:
        raise ValueError(f"split: need at least 2 scenes to split, got {len(trajectories)}")
    for name, points in trajectories.items():
        array = np.asarray(points, dtype=float)
        if array.ndim != 2 or array.shape[0] < 1 or array.shape[1] < 2 or not np.isfinite(array).all():
            raise ValueError(
                f"split: scene {name!r}: trajectory must be finite (N, 2+) points, got {array.shape}"
            )
    groups = location_groups(trajectories, config.overlap_m)
    if len(groups) < 2:
        raise ValueError(
            f"split: all {len(trajectories)} scenes share one location (within {config.overlap_m} m); "
            "no location-disjoint split exists"
        )
    order = np.random.default_rng(config.seed).permutation(len(groups))
    target = config.val_share * len(trajectories)
    val: list[str] = []
    for k in order:
        if not val or len(val) + len(groups[k]) <= target:
            val += groups[k]
        if len(val) >= target:
            break
    if len(val) == len(trajectories):  # the first group alone was everything but another group: keep one out
        val = groups[order[0]]
    train = sorted(set(trajectories) - set(val))
    return Split(train, sorted(val), groups)


def split_dataset(root: Path, out: Path, config: SplitConfig | None = None) -> Split:
    """Split a nuScenes-layout data set's scenes by location; writes the split JSON to `out`."""
    config = config or SplitConfig()
    dataset = load_dataset(Path(root), check_files=False)
    trajectories = {
        scene.name: np.array([img.global_from_ego.translation[:2] for img in scene.all_images()])
        for scene in dataset.scenes
        if scene.all_images()
    }
    split = split_scenes(trajectories, config)
    atomic_write_json(Path(out), {**asdict(split), "config": asdict(config), "dataset": str(root)}, indent=2)
    logger.info(
        "split %d scenes into %d train / %d val (%d locations)",
        len(trajectories),
        len(split.train),
        len(split.val),
        len(split.groups),
    )
    return split
