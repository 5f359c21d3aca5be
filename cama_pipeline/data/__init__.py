"""Loading nuScenes-layout data sets (real nuScenes or the synthetic one) into typed, validated objects."""

from cama_pipeline.data.errors import DatasetError
from cama_pipeline.data.loader import find_version, load_can, load_dataset
from cama_pipeline.data.masks import MaskChoice, mask_roots, masks_fingerprint, parse_mask_choice
from cama_pipeline.data.model import (
    CameraCalibration,
    CameraImage,
    CanData,
    Dataset,
    Frame,
    GnssSeries,
    ImuSeries,
    Pose,
    Scene,
    WheelSeries,
)
from cama_pipeline.data.tables import read_table, read_tables

__all__ = [
    "CameraCalibration",
    "CameraImage",
    "CanData",
    "Dataset",
    "DatasetError",
    "Frame",
    "GnssSeries",
    "ImuSeries",
    "MaskChoice",
    "Pose",
    "Scene",
    "WheelSeries",
    "find_version",
    "load_can",
    "load_dataset",
    "mask_roots",
    "masks_fingerprint",
    "parse_mask_choice",
    "read_table",
    "read_tables",
]
