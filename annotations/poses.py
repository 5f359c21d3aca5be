"""Where an export's ego poses come from: a lookup the exports call per camera image, defined here so that
`annotations` needs nothing from the stages (the refined lookup is built in `cama_pipeline.refined_poses`).

Sources, best first: `sfm` (the image's own SfM pose), `wigo+sfm` (the WIGO trajectory corrected by the SfM
keyframes around it), `wigo` (the WIGO trajectory alone: no SfM keyframe near), `coarse` (the data set's logged
`ego_pose`).
"""

from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

from cama_pipeline.data import CameraImage, Pose

PoseSource = Literal["sfm", "wigo+sfm", "wigo", "coarse"]
POSE_SOURCES: tuple[PoseSource, ...] = ("sfm", "wigo+sfm", "wigo", "coarse")


@dataclass(frozen=True)
class SourcedPose:
    """An image's global_from_ego and where it came from."""

    global_from_ego: Pose
    source: PoseSource


PoseLookup = Callable[[CameraImage], SourcedPose]
"""global_from_ego of a camera image (looked up by its sample_data token, or taken from the image itself)."""


def coarse_pose(image: CameraImage) -> SourcedPose:
    """The data set's logged ego pose of the image: the `coarse` lookup, used only when asked for."""
    return SourcedPose(image.global_from_ego, "coarse")
