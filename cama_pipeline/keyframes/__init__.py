"""Multi-view resynchronisation (<= 40 ms) and keyframe selection by the ego's translation and rotation."""

from cama_pipeline.keyframes.config import KeyframeConfig
from cama_pipeline.keyframes.resync import ImageStamp, SyncedFrame, resync
from cama_pipeline.keyframes.selection import is_stationary, select_keyframes
from cama_pipeline.keyframes.stage import keyframes_of, run

__all__ = [
    "ImageStamp",
    "KeyframeConfig",
    "SyncedFrame",
    "is_stationary",
    "keyframes_of",
    "resync",
    "run",
    "select_keyframes",
]
