"""A site's camera views: every keyframe image with its pose and calibration (global metres, OpenCV camera frame).

Pair selection, features, SfM, the surface, the evaluation, the 3D viewer and the benches all work on these views;
`site_views` builds them from the data set and a site manifest (poses fused by WIGO), and stages that refine
poses replace `world_from_ego`."""

import logging
from dataclasses import dataclass
from typing import Any

import numpy as np

from cama_pipeline.data import Dataset, Pose

logger = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class CameraView:
    """One image with everything geometric the stages need (global metres, OpenCV camera frame)."""

    name: str
    """Image path relative to the data set root: the image's name in the COLMAP database and pair files."""
    token: str
    scene: str
    channel: str
    frame_index: int
    """Index of the image's keyframe within its scene (time order)."""
    timestamp_us: int
    world_from_ego: np.ndarray
    """(4, 4) fused ego pose at the image's time."""
    ego_from_cam: np.ndarray
    """(4, 4) camera extrinsics."""
    intrinsic: np.ndarray
    """(3, 3) pinhole matrix."""
    width: int
    height: int

    @property
    def world_from_cam(self) -> np.ndarray:
        """(4, 4) camera pose in the global frame."""
        return self.world_from_ego @ self.ego_from_cam

    @property
    def center(self) -> np.ndarray:
        """(3,) camera centre in global metres."""
        return self.world_from_cam[:3, 3]

    @property
    def axis(self) -> np.ndarray:
        """(3,) unit optical axis (camera +z) in the global frame."""
        return self.world_from_cam[:3, 2]


def _manifest_pose(entry: dict[str, Any], token: str) -> np.ndarray:
    """global_from_ego of one manifest pose entry; ValueError naming the token when malformed."""
    try:
        return Pose(np.asarray(entry["translation"], float), np.asarray(entry["rotation"], float)).matrix()
    except (KeyError, TypeError, ValueError) as err:
        raise ValueError(f"site manifest: pose of image {token} is malformed ({err})") from None


def site_views(
    dataset: Dataset, manifest: dict[str, Any], *, keyframes_only: bool = True
) -> list[CameraView]:
    """The site's images (keyframes only by default) in scene, frame and channel order, posed by the manifest."""
    views: list[CameraView] = []
    poses: dict[str, Any] = manifest["poses"]
    for scene in manifest["scenes"]:
        frames = [f for f in scene["frames"] if f.get("keyframe") or not keyframes_only]
        for frame_index, frame in enumerate(frames):
            for channel in sorted(frame["images"]):
                token = frame["images"][channel]
                if token not in poses:
                    raise ValueError(f"site manifest: image {token} of scene {scene['scene']} has no pose")
                image = dataset.image(token)
                views.append(
                    CameraView(
                        name=str(image.path.relative_to(dataset.root)),
                        token=token,
                        scene=scene["scene"],
                        channel=channel,
                        frame_index=frame_index,
                        timestamp_us=image.timestamp_us,
                        world_from_ego=_manifest_pose(poses[token], token),
                        ego_from_cam=image.calibration.ego_from_cam.matrix(),
                        intrinsic=np.asarray(image.calibration.intrinsic, float),
                        width=image.calibration.width,
                        height=image.calibration.height,
                    )
                )
    logger.info("%d images from %d scenes", len(views), len(manifest["scenes"]))
    return views
