"""WIGO: wheel + IMU + GNSS pose-graph fusion (gtsam) into 6-DoF ego poses at every camera timestamp."""

from cama_pipeline.wigo.config import WigoConfig
from cama_pipeline.wigo.fusion import FusedPoses, fuse_clip
from cama_pipeline.wigo.inputs import ClipInputs, LoggedPoses, checked_inputs, clip_inputs
from cama_pipeline.wigo.stage import run

__all__ = [
    "ClipInputs",
    "FusedPoses",
    "LoggedPoses",
    "WigoConfig",
    "checked_inputs",
    "clip_inputs",
    "fuse_clip",
    "run",
]
