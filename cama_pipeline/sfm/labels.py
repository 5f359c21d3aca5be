"""Per-point semantic labels of a sparse model: the majority class of the semantic masks at the point's
2D observations, mapped to the BEV raster classes (road, curb, lane marking, crosswalk; anything else is
background); and the labelled sparse points the SfM stage stores."""

import logging
from collections.abc import Callable

import numpy as np
import pycolmap

from cama_pipeline.cameras import CameraView
from cama_pipeline.data import Dataset
from cama_pipeline.semantics import BEV_CLASSES, Semantic
from cama_pipeline.sfm.io import SparsePoints

logger = logging.getLogger(__name__)

MaskReader = Callable[[str], np.ndarray | None]
"""Image name -> (H, W) semantic mask (class ids), None when the image has none."""
VOTE_CLASSES = len(Semantic.__members__)


def _votes_of_image(
    image: pycolmap.Image, mask: np.ndarray, row_of_point: dict[int, int], votes: np.ndarray
) -> None:
    """Add the image's observations (mask class at each observed keypoint) to `votes` (points x classes)."""
    observed = [(p.xy, row_of_point[p.point3D_id]) for p in image.points2D if p.has_point3D()]
    if not observed:
        return
    xy = np.array([o[0] for o in observed], dtype=np.float64)
    rows = np.array([o[1] for o in observed], dtype=np.int64)
    height, width = mask.shape
    # COLMAP keypoints have pixel centres at .5; masks index pixels by their integer corner.
    cols_px = np.clip(np.floor(xy[:, 0]).astype(int), 0, width - 1)
    rows_px = np.clip(np.floor(xy[:, 1]).astype(int), 0, height - 1)
    classes = np.asarray(mask[rows_px, cols_px], dtype=np.int64)
    known = classes < VOTE_CLASSES
    np.add.at(votes, (rows[known], classes[known]), 1)


def point_labels(
    reconstruction: pycolmap.Reconstruction, point_ids: list[int], read_mask: MaskReader
) -> np.ndarray:
    """(N,) uint8 BEV class of each point in `point_ids` order (background when no mask saw it)."""
    row_of_point = {pid: row for row, pid in enumerate(point_ids)}
    votes = np.zeros((len(point_ids), VOTE_CLASSES), dtype=np.int64)
    missing = 0
    for image in reconstruction.images.values():
        if not image.has_pose:
            continue
        mask = read_mask(image.name)
        if mask is None:
            missing += 1
            continue
        _votes_of_image(image, mask, row_of_point, votes)
    if missing:
        logger.warning("%d image(s) without a semantic mask: their observations cast no label vote", missing)
    majority = votes.argmax(axis=1)
    labels = np.where(np.isin(majority, [int(c) for c in BEV_CLASSES]), majority, int(Semantic.BACKGROUND))
    labels[votes.sum(axis=1) == 0] = int(Semantic.BACKGROUND)
    return labels.astype(np.uint8)


def dataset_masks(dataset: Dataset, views: list[CameraView]) -> MaskReader:
    """Semantic mask by image name, read from the data set (None when the image has none)."""
    token_of = {view.name: view.token for view in views}

    def read(name: str) -> np.ndarray | None:
        image = dataset.image(token_of[name])
        return image.load_semantic() if image.semantic_mask_path is not None else None

    return read


def sparse_points(reconstruction: pycolmap.Reconstruction, read_mask: MaskReader) -> SparsePoints:
    """The model's points with their labels, errors and track lengths (point id order)."""
    ids = sorted(reconstruction.point3D_ids())
    points = [reconstruction.point3D(pid) for pid in ids]
    return SparsePoints(
        xyz=np.array([p.xyz for p in points], dtype=np.float64).reshape(-1, 3),
        label=point_labels(reconstruction, ids, read_mask),
        error_px=np.array([p.error for p in points], dtype=np.float64),
        track_length=np.array([p.track.length() for p in points], dtype=np.int32),
    )
