"""The known-pose model SfM starts from: a working COLMAP database holding exactly the given views, with
their rig and keyframes, and the reconstruction loaded from it with every keyframe posed by odometry.

The site's database (written by `cama_pipeline.features`) has one camera per distinct calibration and no
rigs; the working database copies the views' keypoints and verified matches, adds its own cameras
(principal point moved to COLMAP's pixel convention) and groups images into frames: one frame per keyframe
on a rig of its channels (rigid BA; motion-compensated, so one rig per keyframe unless the extrinsics are
refined) or one frame per image on a trivial rig (plain BA). Image ids are the site database's.
"""

import logging
from collections import defaultdict
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pycolmap

from cama_pipeline.cameras import CameraView
from cama_pipeline.sfm.config import SfmConfig
from cama_pipeline.sfm.errors import SfmError

logger = logging.getLogger(__name__)
REFERENCE_CHANNEL = "CAM_FRONT"


def rigid_from_matrix(a_from_b: np.ndarray) -> pycolmap.Rigid3d:
    """A (4, 4) or (3, 4) transform as pycolmap's Rigid3d."""
    return pycolmap.Rigid3d(np.asarray(a_from_b, float)[:3, :4])


def matrix_from_rigid(a_from_b: pycolmap.Rigid3d) -> np.ndarray:
    """Rigid3d as a (4, 4) matrix."""
    matrix = np.eye(4)
    matrix[:3, :4] = a_from_b.matrix()
    return matrix


def frame_pose(reconstruction: pycolmap.Reconstruction, frame_id: int) -> pycolmap.Rigid3d:
    """The frame's rig_from_world (a live view: its `params` are what BA optimises)."""
    pose = reconstruction.frame(frame_id).rig_from_world
    if pose is None:
        raise SfmError(f"frame {frame_id} has no pose")
    return pose


@dataclass(frozen=True, eq=False)
class FrameInfo:
    """What the model remembers of one frame: its clip and order, its images, its odometry pose."""

    frame_id: int
    scene: str
    channel: str
    """The rig's reference camera (CAM_FRONT for a keyframe; the image's own channel in plain BA)."""
    frame_index: int
    initial_rig_from_world: np.ndarray
    """(4, 4) the odometry pose the frame started from."""
    image_names: tuple[str, ...]


@dataclass(eq=False)
class GuidedModel:
    """A reconstruction of known-pose views and the bookkeeping to read refined ego poses back."""

    reconstruction: pycolmap.Reconstruction
    frames: dict[int, FrameInfo]
    image_ids: dict[str, int]
    """Image id by view name."""
    mapper: pycolmap.IncrementalMapper
    """COLMAP's mapper over the working database: triangulation, retriangulation and point filtering."""
    cache: pycolmap.DatabaseCache
    """The mapper's database cache (the mapper needs it alive)."""
    flagged: dict[str, str] = field(default_factory=dict)
    """Dropped image names with the reason."""

    def ordered_frames(self) -> list[FrameInfo]:
        """Frames in clip and time order (consecutive entries of one scene are odometry neighbours)."""
        return sorted(self.frames.values(), key=lambda f: (f.scene, f.frame_index, f.channel))

    def registered_frame_ids(self) -> list[int]:
        """Ids of the frames still registered, in clip and time order."""
        registered = set(self.reconstruction.reg_frame_ids())
        return [f.frame_id for f in self.ordered_frames() if f.frame_id in registered]

    def drop_frame(self, frame_id: int, reason: str) -> None:
        """Deregister a frame (its observations go) and flag its images with the reason."""
        self.mapper.observation_manager.deregister_frame(frame_id)
        for name in self.frames[frame_id].image_names:
            self.flagged[name] = reason
        logger.info("frame %d (%s) dropped: %s", frame_id, self.frames[frame_id].image_names[0], reason)


def _calibration_key(view: CameraView) -> tuple[float, ...]:
    k = view.intrinsic
    return (k[0, 0], k[1, 1], k[0, 2], k[1, 2], float(view.width), float(view.height))


def _rig_key(views: Sequence[CameraView]) -> tuple[object, ...]:
    """Views share a rig when every channel has the same calibration and extrinsics."""
    return tuple(
        (v.channel, _calibration_key(v), tuple(np.round(v.ego_from_cam, 9).ravel()))
        for v in sorted(views, key=lambda v: v.channel)
    )


def _reference(views: Sequence[CameraView]) -> CameraView:
    """CAM_FRONT when the keyframe has it, else its first channel by name."""
    by_channel = {v.channel: v for v in views}
    return by_channel.get(REFERENCE_CHANNEL) or by_channel[min(by_channel)]


class _Builder:
    """Writes cameras, rigs, frames and images into the working database, consistent ids throughout."""

    def __init__(
        self, source: pycolmap.Database, target: pycolmap.Database, *, motion_compensated: bool
    ) -> None:
        self.source, self.target = source, target
        self.motion_compensated = motion_compensated
        self.cameras: dict[tuple[object, ...], pycolmap.Camera] = {}
        self.rigs: dict[tuple[object, ...], int] = {}
        self.image_ids: dict[str, int] = {}
        self.frames: dict[int, FrameInfo] = {}

    def camera(self, view: CameraView) -> pycolmap.Camera:
        """The camera of the view's channel and calibration (and keyframe, with motion-compensated rigs: a
        COLMAP camera belongs to one rig). COLMAP puts the top-left pixel's centre at (0.5, 0.5) (its SIFT
        keypoints too), OpenCV at (0, 0): the principal point moves by half a pixel."""
        key = (view.channel, _calibration_key(view), self._rig_scope(view))
        if key not in self.cameras:
            fx, fy, cx, cy, width, height = _calibration_key(view)
            camera = pycolmap.Camera(
                camera_id=len(self.cameras) + 1,
                model="PINHOLE",
                width=int(width),
                height=int(height),
                params=[fx, fy, cx + 0.5, cy + 0.5],
            )
            self.target.write_camera(camera, use_camera_id=True)
            self.cameras[key] = camera
        return self.cameras[key]

    def _rig_scope(self, view: CameraView) -> tuple[str, int] | None:
        """The keyframe a rig (and its cameras) is private to, when rigs are motion-compensated."""
        return (view.scene, view.frame_index) if self.motion_compensated else None

    def rig(self, views: Sequence[CameraView]) -> int:
        """The rig of these images (one frame's), reference camera first; created when new.

        Motion-compensated (the default for rigid BA): each keyframe gets its own rig whose camera-to-rig
        transforms add the ego motion between the cameras' capture times (from the odometry; tens of ms
        apart, i.e. decimetres at speed). Static: one rig per calibration, shared by all keyframes."""
        key = (self._rig_scope(views[0]), _rig_key(views))
        if key not in self.rigs:
            reference = _reference(views)
            rig = pycolmap.Rig(rig_id=len(self.rigs) + 1)
            rig.add_ref_sensor(self.camera(reference).sensor_id)
            for view in views:
                if view is not reference:
                    cam_from_ref = np.linalg.inv(view.ego_from_cam) @ reference.ego_from_cam
                    if self.motion_compensated:
                        cam_from_ref = np.linalg.inv(view.world_from_cam) @ reference.world_from_cam
                    rig.add_sensor(self.camera(view).sensor_id, rigid_from_matrix(cam_from_ref))
            self.target.write_rig(rig, use_rig_id=True)
            self.rigs[key] = rig.rig_id
        return self.rigs[key]

    def frame(self, views: Sequence[CameraView]) -> None:
        """One frame of these images (a keyframe's, or a single image's), with its odometry pose."""
        reference = _reference(views)
        frame = pycolmap.Frame(frame_id=len(self.frames) + 1, rig_id=self.rig(views))
        for view in views:
            image_id = self.image(view)
            frame.add_data_id(pycolmap.data_t(self.camera(view).sensor_id, image_id))
        self.target.write_frame(frame, use_frame_id=True)
        world_from_rig = reference.world_from_ego @ reference.ego_from_cam
        self.frames[frame.frame_id] = FrameInfo(
            frame_id=frame.frame_id,
            scene=reference.scene,
            channel=reference.channel,
            frame_index=reference.frame_index,
            initial_rig_from_world=np.linalg.inv(world_from_rig),
            image_names=tuple(v.name for v in views),
        )

    def image(self, view: CameraView) -> int:
        stored = self.source.read_image_with_name(view.name)
        if stored is None:
            raise SfmError(f"image {view.name} (scene {view.scene}) is not in the features database")
        image = pycolmap.Image(
            name=view.name, camera_id=self.camera(view).camera_id, image_id=stored.image_id
        )
        self.target.write_image(image, use_image_id=True)
        self.target.write_keypoints(stored.image_id, self.source.read_keypoints(stored.image_id)[:, :2])
        self.image_ids[view.name] = stored.image_id
        return int(stored.image_id)

    def matches(self) -> int:
        """Copy the verified matches between the model's images; returns the number of pairs."""
        wanted = set(self.image_ids.values())
        pair_ids, geometries = self.source.read_two_view_geometries()
        copied = 0
        for pair_id, geometry in zip(pair_ids, geometries, strict=True):
            first, second = pycolmap.pair_id_to_image_pair(pair_id)
            if first in wanted and second in wanted and len(geometry.inlier_matches) > 0:
                self.target.write_two_view_geometry(first, second, geometry)
                copied += 1
        return copied


def _group(views: Sequence[CameraView], rigid: bool) -> list[list[CameraView]]:
    """Images grouped into frames: by keyframe (rigid) or one each (plain)."""
    if not rigid:
        return [[view] for view in views]
    groups: dict[tuple[str, int], list[CameraView]] = defaultdict(list)
    for view in views:
        groups[(view.scene, view.frame_index)].append(view)
    return [groups[key] for key in sorted(groups)]


def clip_label(views: Sequence[CameraView]) -> str:
    """The scenes of these views, for messages."""
    scenes = sorted({view.scene for view in views})
    return ", ".join(scenes[:4]) + (f" (+{len(scenes) - 4} more)" if len(scenes) > 4 else "")


def write_working_database(
    views: Sequence[CameraView],
    source_path: Path,
    target_path: Path,
    *,
    rigid: bool,
    motion_compensated: bool,
) -> tuple[dict[int, FrameInfo], dict[str, int], int]:
    """Write the working database of `views` (see the module docstring); frames, image ids, matched pairs."""
    if not Path(source_path).is_file():
        raise FileNotFoundError(f"{source_path}: features database not found; run `cama features` first")
    target_path.unlink(missing_ok=True)
    source = pycolmap.Database.open(str(source_path))
    target = pycolmap.Database.open(str(target_path))
    try:
        builder = _Builder(source, target, motion_compensated=motion_compensated)
        for group in _group(views, rigid):
            builder.frame(group)
        pairs = builder.matches()
    finally:
        target.close()
        source.close()
    return builder.frames, builder.image_ids, pairs


def build_model(
    views: Sequence[CameraView], source_path: Path, work_dir: Path, config: SfmConfig
) -> GuidedModel:
    """The known-pose model of `views` with a mapper on it, every frame registered at its odometry pose
    (rigs motion-compensated in rigid BA unless the extrinsics are refined)."""
    names = [view.name for view in views]
    if len(set(names)) != len(names):
        raise ValueError("reconstruct_views: the views contain duplicate image names")
    work_dir.mkdir(parents=True, exist_ok=True)
    database = work_dir / "working.db"
    frames, image_ids, pairs = write_working_database(
        views,
        source_path,
        database,
        rigid=config.rigid,
        motion_compensated=config.rigid and not config.refine_extrinsics,
    )
    if pairs == 0:
        raise SfmError(f"clip {clip_label(views)}: no verified matches among its {len(views)} images")
    db = pycolmap.Database.open(str(database))
    try:
        cache = pycolmap.DatabaseCache.create(db, pycolmap.DatabaseCacheOptions())
    finally:
        db.close()
    reconstruction = pycolmap.Reconstruction()
    mapper = pycolmap.IncrementalMapper(cache)
    mapper.begin_reconstruction(reconstruction)
    for frame in frames.values():
        if reconstruction.exists_frame(frame.frame_id):  # frames without any match are not loaded
            reconstruction.frame(frame.frame_id).rig_from_world = rigid_from_matrix(
                frame.initial_rig_from_world
            )
            mapper.observation_manager.register_frame(frame.frame_id)
    return GuidedModel(reconstruction, frames, image_ids, mapper, cache)
