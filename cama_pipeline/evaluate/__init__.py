"""Evaluation of map annotations: SRE / precision / recall / F1 against image lane instances (CAMAv2
Algorithm 2), MapTR Chamfer-AP, and pose / elevation errors against ground truth."""

from cama_pipeline.evaluate.chamfer_ap import (
    ChamferApConfig,
    ChamferApResult,
    MapVector,
    chamfer_ap,
    chamfer_distance,
)
from cama_pipeline.evaluate.errors import ElevationErrors, PoseErrors, elevation_errors, pose_errors
from cama_pipeline.evaluate.inputs import (
    EvaluationInputError,
    VectorElement,
    load_true_poses,
    load_vector_map,
)
from cama_pipeline.evaluate.projection import (
    PinholeCamera,
    ProjectedPiece,
    ProjectionConfig,
    project_polyline,
)
from cama_pipeline.evaluate.sre import SreConfig, extract_instances, match_image
from cama_pipeline.evaluate.sre_cama_config import SRE_PROTOCOLS, CamaProtocolConfig, SreProtocol
from cama_pipeline.evaluate.sre_dataset import evaluate_sre, sre_for_dataset
from cama_pipeline.evaluate.sre_report import ImageSre, SreReport, SreSummary

__all__ = [
    "SRE_PROTOCOLS",
    "CamaProtocolConfig",
    "ChamferApConfig",
    "ChamferApResult",
    "ElevationErrors",
    "EvaluationInputError",
    "ImageSre",
    "MapVector",
    "PinholeCamera",
    "PoseErrors",
    "ProjectedPiece",
    "ProjectionConfig",
    "SreConfig",
    "SreProtocol",
    "SreReport",
    "SreSummary",
    "VectorElement",
    "chamfer_ap",
    "chamfer_distance",
    "elevation_errors",
    "evaluate_sre",
    "extract_instances",
    "load_true_poses",
    "load_vector_map",
    "match_image",
    "pose_errors",
    "project_polyline",
    "sre_for_dataset",
]
