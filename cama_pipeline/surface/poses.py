"""The keyframe cameras of a site posed by the chosen source: ground truth (synthetic only), WIGO or SfM."""

import json
import logging
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from cama_pipeline.cameras import CameraView, site_views
from cama_pipeline.data import Dataset, Pose
from cama_pipeline.sfm.io import read_refined_poses
from cama_pipeline.surface.config import POSE_SOURCES
from cama_pipeline.workspace import Workspace

logger = logging.getLogger(__name__)


def ground_truth_poses_path(dataset_root: Path) -> Path:
    """`<data set root's parent>/ground_truth/poses.json`, written by the synthetic generator."""
    return Path(dataset_root).absolute().parent / "ground_truth" / "poses.json"


def _ground_truth_poses(dataset_root: Path) -> dict[str, np.ndarray]:
    """sample_data token -> (4, 4) true world_from_ego; errors name the file."""
    path = ground_truth_poses_path(dataset_root)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: not found; ground-truth poses exist only for synthetic sites")
    try:
        data: dict[str, Any] = json.loads(path.read_text(encoding="utf-8"))
        return {
            token: Pose(np.asarray(e["translation"], float), np.asarray(e["rotation"], float)).matrix()
            for token, e in data.items()
        }
    except (json.JSONDecodeError, AttributeError, KeyError, TypeError, ValueError) as err:
        raise ValueError(f"{path}: not a token -> {{translation, rotation}} map ({err})") from None


def pose_inputs(dataset_root: Path, workspace: Workspace, site_id: str, source: str) -> list[Path]:
    """The files the chosen poses come from (besides the site manifest), for the fingerprint."""
    if source == "ground_truth":
        return [ground_truth_poses_path(dataset_root)]
    if source == "sfm":
        return [workspace.sfm_poses(site_id)]
    return []


def posed_views(
    dataset: Dataset, manifest: dict[str, Any], workspace: Workspace, site_id: str, source: str
) -> list[CameraView]:
    """The site's keyframe views with `source`'s ego poses; views the source has no pose for are dropped."""
    if source not in POSE_SOURCES:
        raise ValueError(f"poses must be one of {', '.join(POSE_SOURCES)}, got {source!r}")
    views = site_views(dataset, manifest)
    if source == "wigo":
        return views
    poses = (
        _ground_truth_poses(dataset.root)
        if source == "ground_truth"
        else read_refined_poses(workspace.sfm_poses(site_id))
    )
    posed = [replace(v, world_from_ego=poses[v.token]) for v in views if v.token in poses]
    if len(posed) < len(views):
        logger.warning(
            "%s poses: %d of %d keyframe images have none, left out",
            source,
            len(views) - len(posed),
            len(views),
        )
    return posed
