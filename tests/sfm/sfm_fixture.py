"""Shared SfM test inputs: the tiny site run through wigo -> keyframes -> sites -> pairs -> features.

`build_sfm_inputs` is a plain function (so other test folders and scripts can call it); the session
fixture `sfm_inputs` in `tests/sfm/conftest.py` builds it once per test session.
"""

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cama_pipeline.cameras import CameraView, site_views
from cama_pipeline.data import Pose, load_dataset
from cama_pipeline.features.config import FeaturesConfig
from cama_pipeline.features.stage import run as run_features
from cama_pipeline.pairs.config import PairsConfig
from cama_pipeline.pairs.stage import run as run_pairs
from cama_pipeline.site.io import read_site_manifest
from cama_pipeline.workspace import Workspace
from tests.pairs.site_workspace import build_site_workspace

SITE_ID = "site-001"


@dataclass(frozen=True, eq=False)
class SfmInputs:
    """Everything SfM needs for the tiny site, built by the real upstream stages."""

    dataset_root: Path
    """The data set root: also the image folder (image names are relative to it)."""
    workspace: Path
    site_id: str
    database: Path
    """The site's COLMAP database (features and verified matches)."""
    views: tuple[CameraView, ...]
    """Every keyframe image of the site, posed by WIGO (the manifest's poses)."""
    true_world_from_ego: dict[str, np.ndarray]
    """True (4, 4) ego pose by image name, from the generator's ground truth."""

    @property
    def image_dir(self) -> Path:
        """Folder the image names are relative to."""
        return self.dataset_root

    def scene_views(self, scene: str) -> list[CameraView]:
        """The views of one scene (clip), in frame and channel order."""
        return [view for view in self.views if view.scene == scene]

    def longest_drive(self) -> list[CameraView]:
        """The views of the scene whose keyframes span the longest distance (a moving clip)."""

        def span(scene: str) -> float:
            centres = np.array([v.world_from_ego[:3, 3] for v in self.scene_views(scene)])
            return float(np.linalg.norm(centres.max(axis=0) - centres.min(axis=0)))

        return self.scene_views(max(self.scenes, key=span))

    @property
    def scenes(self) -> list[str]:
        """Scenes of the site with images, in manifest order."""
        return list(dict.fromkeys(view.scene for view in self.views))


def _true_poses(truth_file: Path, views: list[CameraView]) -> dict[str, np.ndarray]:
    """True world_from_ego by image name."""
    truth = json.loads(truth_file.read_text())
    return {
        view.name: Pose(
            np.asarray(truth[view.token]["translation"], float),
            np.asarray(truth[view.token]["rotation"], float),
        ).matrix()
        for view in views
    }


def build_sfm_inputs(tiny_site_root: Path, tmp_dir: Path) -> SfmInputs:
    """Run the upstream stages on the generated site at `tiny_site_root` into a workspace under `tmp_dir`."""
    dataset_root = Path(tiny_site_root) / "nuscenes"
    workspace = build_site_workspace(dataset_root, Path(tmp_dir) / "workspace")
    run_pairs(PairsConfig(), dataset_root, workspace)
    run_features(FeaturesConfig(num_threads=1), dataset_root, workspace)
    ws = Workspace(workspace)
    views = site_views(load_dataset(dataset_root), read_site_manifest(ws.site_manifest(SITE_ID)))
    truth = _true_poses(Path(tiny_site_root) / "ground_truth" / "poses.json", views)
    return SfmInputs(dataset_root, workspace, SITE_ID, ws.features_db(SITE_ID), tuple(views), truth)


def pose_errors(world_from_ego: dict[str, np.ndarray], truth: dict[str, np.ndarray]) -> tuple[float, float]:
    """Mean position error (m) and mean rotation error (deg) of ego poses by image name against the truth."""
    positions, angles = [], []
    for name, pose in world_from_ego.items():
        positions.append(float(np.linalg.norm(pose[:3, 3] - truth[name][:3, 3])))
        relative = pose[:3, :3].T @ truth[name][:3, :3]
        angles.append(float(np.degrees(np.arccos(np.clip((np.trace(relative) - 1) / 2, -1.0, 1.0)))))
    return float(np.mean(positions)), float(np.mean(angles))


def relative_pose_errors(
    world_from_ego: dict[str, np.ndarray], truth: dict[str, np.ndarray], anchor: str
) -> tuple[float, float]:
    """`pose_errors` of the poses relative to the anchor image's (the clip's own frame: free of the
    absolute offset that GNSS leaves in the odometry and that no SfM can see)."""
    base, true_base = np.linalg.inv(world_from_ego[anchor]), np.linalg.inv(truth[anchor])
    return pose_errors(
        {name: base @ pose for name, pose in world_from_ego.items()},
        {name: true_base @ truth[name] for name in world_from_ego},
    )
