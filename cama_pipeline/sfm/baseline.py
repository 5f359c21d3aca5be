"""The comparison point of the SfM benchmark: COLMAP's incremental mapping on the same database (no poses
used), brought into the global frame by a similarity to reference camera centres, and camera pose errors of
any model against reference poses."""

import logging
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pycolmap

from cama_pipeline.sfm.merge import robust_similarity

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class PoseErrors:
    """Camera pose errors of a model's registered images against reference poses."""

    images: int
    """Images the reference has."""
    registered: int
    """Of those, registered in the model."""
    position_cm: float
    """Mean camera centre error, centimetres."""
    rotation_deg: float
    """Mean camera orientation error, degrees."""
    position_cm_median: float
    rotation_deg_median: float

    @property
    def registered_ratio(self) -> float:
        return self.registered / self.images if self.images else 0.0


def incremental_model(
    database: Path,
    image_dir: Path,
    image_names: list[str],
    *,
    num_threads: int = 1,
    max_seconds: int | None = None,
) -> pycolmap.Reconstruction | None:
    """The largest model of incremental mapping over `image_names` (a copy of the database is used);
    with `max_seconds` COLMAP stops mapping after that long and the model is what it had registered."""
    if max_seconds is not None and max_seconds < 1:
        raise ValueError(f"incremental_model: max_seconds must be >= 1, got {max_seconds}")
    with tempfile.TemporaryDirectory(prefix="cama-incremental-") as scratch:
        copy = Path(scratch) / "database.db"
        shutil.copyfile(database, copy)
        options = pycolmap.IncrementalPipelineOptions()
        options.image_names = list(image_names)
        options.num_threads = num_threads
        options.random_seed = 0
        options.max_runtime_seconds = max_seconds if max_seconds is not None else -1
        models = pycolmap.incremental_mapping(copy, image_dir, Path(scratch) / "out", options=options)
    if not models:
        logger.warning("incremental mapping registered no model")
        return None
    return max(models.values(), key=lambda model: model.num_reg_images())


def camera_centres(model: pycolmap.Reconstruction) -> dict[str, np.ndarray]:
    """Registered image name -> (3,) camera centre in the model's frame."""
    return {image.name: image.projection_center() for image in model.images.values() if image.has_pose}


def align_to_reference(model: pycolmap.Reconstruction, reference_centres: dict[str, np.ndarray]) -> bool:
    """Move `model` (in place) by the similarity that best maps its camera centres onto the reference ones
    (LO-RANSAC, 0.5 m inliers); False when fewer than 3 images are shared or no similarity is found."""
    centres = camera_centres(model)
    names = sorted(set(centres) & set(reference_centres))
    if len(names) < 3:
        return False
    source = np.array([centres[n] for n in names])
    target = np.array([reference_centres[n] for n in names])
    found = robust_similarity(source, target, max_error_m=0.5)
    if found is None:
        return False
    model.transform(found[0])
    return True


def aligned_poses(
    estimated_world_from_cam: dict[str, np.ndarray], reference_world_from_cam: dict[str, np.ndarray]
) -> dict[str, np.ndarray]:
    """The estimated camera poses moved by the similarity that best maps their centres onto the reference
    ones (gauge-free comparison); unchanged when fewer than 3 are shared or no similarity is found."""
    names = sorted(set(estimated_world_from_cam) & set(reference_world_from_cam))
    if len(names) < 3:
        return estimated_world_from_cam
    source = np.array([estimated_world_from_cam[n][:3, 3] for n in names])
    found = robust_similarity(source, np.array([reference_world_from_cam[n][:3, 3] for n in names]), 0.5)
    if found is None:
        return estimated_world_from_cam
    similarity = found[0].matrix()
    rotation = similarity[:, :3] / found[0].scale
    moved = {}
    for name, pose in estimated_world_from_cam.items():
        out = np.eye(4)
        out[:3, :3] = rotation @ pose[:3, :3]
        out[:3, 3] = similarity[:, :3] @ pose[:3, 3] + similarity[:, 3]
        moved[name] = out
    return moved


def model_poses(model: pycolmap.Reconstruction) -> dict[str, np.ndarray]:
    """Registered image name -> (4, 4) world_from_cam of the model."""
    return {
        image.name: image.cam_from_world().inverse().matrix()
        for image in model.images.values()
        if image.has_pose
    }


def pose_errors(
    estimated_world_from_cam: dict[str, np.ndarray], reference_world_from_cam: dict[str, np.ndarray]
) -> PoseErrors:
    """Centre and orientation errors of estimated camera poses against reference ones, both (4, 4)
    world_from_cam (3x4 accepted) by image name; images the reference lacks are ignored."""
    names = [name for name in estimated_world_from_cam if name in reference_world_from_cam]
    if not names:
        nan = float("nan")
        return PoseErrors(len(reference_world_from_cam), 0, nan, nan, nan, nan)
    estimated = np.array([estimated_world_from_cam[n][:3, :4] for n in names])
    reference = np.array([reference_world_from_cam[n][:3, :4] for n in names])
    positions = np.linalg.norm(estimated[:, :, 3] - reference[:, :, 3], axis=1) * 100
    relative = np.einsum("nji,njk->nik", estimated[:, :, :3], reference[:, :, :3])
    cosines = np.clip((np.trace(relative, axis1=1, axis2=2) - 1) / 2, -1, 1)
    rotations = np.degrees(np.arccos(cosines))
    return PoseErrors(
        images=len(reference_world_from_cam),
        registered=len(names),
        position_cm=float(positions.mean()),
        rotation_deg=float(rotations.mean()),
        position_cm_median=float(np.median(positions)),
        rotation_deg_median=float(np.median(rotations)),
    )
