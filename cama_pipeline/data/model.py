"""Typed, immutable view of a loaded nuScenes-layout data set: poses, cameras, images, frames, scenes, CAN."""

import math
import os
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import TypeVar

import cv2
import numpy as np

from cama_pipeline.data.errors import DatasetError

_T = TypeVar("_T")


def _frozen_array(values: object, shape: tuple[int, ...], name: str, dtype: type = np.float64) -> np.ndarray:
    """Copy `values` into a read-only array of `shape` (-1 = any length), or raise ValueError naming it."""
    array: np.ndarray = np.array(values, dtype=dtype)
    if array.ndim != len(shape) or any(
        want not in (-1, got) for want, got in zip(shape, array.shape, strict=True)
    ):
        wanted = "x".join("N" if n == -1 else str(n) for n in shape)
        raise ValueError(f"{name} must have shape ({wanted}), got {array.shape}")
    array.setflags(write=False)
    return array


def quaternion_to_matrix(q: np.ndarray) -> np.ndarray:
    """3x3 rotation matrix of a unit quaternion [w, x, y, z]."""
    w, x, y, z = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def quaternion_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product a * b of quaternions [w, x, y, z] (rotation b first, then a)."""
    aw, av = a[0], a[1:]
    bw, bv = b[0], b[1:]
    return np.concatenate([[aw * bw - av @ bv], aw * bv + bw * av + np.cross(av, bv)])


@dataclass(frozen=True, eq=False)
class Pose:
    """Rigid transform `a_from_b` (named so where held, e.g. `global_from_ego`): maps b points into a."""

    translation: np.ndarray
    """(3,) metres: the origin of frame b expressed in frame a."""
    rotation: np.ndarray
    """(4,) unit quaternion [w, x, y, z] rotating b vectors into a (normalised on creation)."""

    def __post_init__(self) -> None:
        translation = np.array(self.translation, dtype=np.float64)
        rotation = np.array(self.rotation, dtype=np.float64)
        if translation.shape != (3,) or rotation.shape != (4,):
            raise ValueError(
                f"translation must have shape (3,) and rotation (a quaternion [w, x, y, z]) shape (4,), "
                f"got {translation.shape} and {rotation.shape}"
            )
        if not (np.isfinite(translation).all() and np.isfinite(rotation).all()):
            raise ValueError("translation and rotation must be finite")
        norm = math.hypot(*rotation)
        if norm < 1e-9:
            raise ValueError("rotation quaternion has zero norm")
        rotation /= norm
        translation.setflags(write=False)
        rotation.setflags(write=False)
        object.__setattr__(self, "translation", translation)
        object.__setattr__(self, "rotation", rotation)

    @classmethod
    def identity(cls) -> "Pose":
        """The transform that changes nothing."""
        return cls(np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0]))

    def rotation_matrix(self) -> np.ndarray:
        """3x3 rotation matrix."""
        return quaternion_to_matrix(self.rotation)

    def matrix(self) -> np.ndarray:
        """4x4 homogeneous matrix."""
        out = np.eye(4)
        out[:3, :3] = self.rotation_matrix()
        out[:3, 3] = self.translation
        return out

    def inverse(self) -> "Pose":
        """`b_from_a` of this `a_from_b`."""
        conjugate = self.rotation * np.array([1.0, -1.0, -1.0, -1.0])
        return Pose(-(quaternion_to_matrix(conjugate) @ self.translation), conjugate)

    def __matmul__(self, other: "Pose") -> "Pose":
        """Compose: `a_from_b @ b_from_c` is `a_from_c`."""
        return Pose(
            self.rotation_matrix() @ other.translation + self.translation,
            quaternion_multiply(self.rotation, other.rotation),
        )

    def transform_points(self, points: np.ndarray) -> np.ndarray:
        """Map (N, 3) points from frame b into frame a."""
        return np.asarray(points, dtype=np.float64) @ self.rotation_matrix().T + self.translation


@dataclass(frozen=True, eq=False)
class CameraCalibration:
    """One camera's calibration (a `calibrated_sensor` record) with the image size it goes with."""

    token: str
    """calibrated_sensor token."""
    channel: str
    """Sensor channel, e.g. `CAM_FRONT`."""
    ego_from_cam: Pose
    """Camera (OpenCV axes) to ego frame."""
    intrinsic: np.ndarray
    """(3, 3) pinhole matrix K in pixels."""
    width: int
    """Image width in pixels."""
    height: int
    """Image height in pixels."""

    def __post_init__(self) -> None:
        intrinsic = _frozen_array(self.intrinsic, (3, 3), "intrinsic")
        if not np.all(np.isfinite(intrinsic)):
            raise ValueError("intrinsic must be finite")
        if self.width <= 0 or self.height <= 0:
            raise ValueError(f"image size must be positive, got {self.width}x{self.height}")
        object.__setattr__(self, "intrinsic", intrinsic)


def _read_image(path: Path | None, flags: int, what: str, token: str) -> np.ndarray:
    """Read an image with OpenCV; a missing or undecodable file is a DatasetError naming it."""
    if path is None:
        raise DatasetError(f"no {what} for this image in the data set", record=token)
    if not os.path.exists(path):
        raise DatasetError(f"{what} file not found", path=path, record=token)
    image = cv2.imread(str(path), flags)
    if image is None:
        raise DatasetError(f"{what} file cannot be decoded", path=path, record=token)
    return image


@dataclass(frozen=True, eq=False)
class CameraImage:
    """One camera image (a camera `sample_data` record): where it is, when, and from which pose."""

    token: str
    """sample_data token."""
    sample_token: str
    """The sample (key frame) this image belongs to; sweeps point to a nearby sample."""
    channel: str
    """Camera channel, e.g. `CAM_FRONT`."""
    timestamp_us: int
    """Capture time in microseconds."""
    is_key_frame: bool
    """True for images in `samples/`, false for sweeps."""
    path: Path
    """Absolute path of the image file."""
    global_from_ego: Pose
    """Coarse ego pose at capture time (the `ego_pose` record)."""
    calibration: CameraCalibration
    """Intrinsics, extrinsics and size of the camera."""
    semantic_mask_path: Path | None = None
    """Absolute path of the uint8 semantic mask (cama_pipeline.semantics ids), None when absent."""
    instance_mask_path: Path | None = None
    """Absolute path of the uint16 instance mask (class * 1000 + index), None when absent."""

    @property
    def global_from_cam(self) -> Pose:
        """Camera to global frame, through the coarse ego pose."""
        return self.global_from_ego @ self.calibration.ego_from_cam

    def _check_size(self, image: np.ndarray, path: Path | None, what: str) -> np.ndarray:
        """Raise if `image` does not have the calibrated size."""
        expected = (self.calibration.height, self.calibration.width)
        if image.shape[:2] != expected:
            got = f"{image.shape[1]}x{image.shape[0]}"
            raise DatasetError(
                f"{what} is {got} px, sample_data says {expected[1]}x{expected[0]} px",
                path=path,
                record=self.token,
            )
        return image

    def _require_mask(self, path: Path | None, what: str) -> None:
        """A DatasetError naming the image when none of the mask roots holds its mask, and the way out."""
        if path is None:
            raise DatasetError(
                f"no {what} for this image in the mask folders searched; make masks with `cama segment` or "
                "`cama import-masks`, or name other ones with --masks",
                path=self.path,
                record=self.token,
            )

    def load_rgb(self) -> np.ndarray:
        """The image as (H, W, 3) RGB uint8."""
        bgr = _read_image(self.path, cv2.IMREAD_COLOR, "image", self.token)
        return self._check_size(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB), self.path, "image")

    def load_semantic(self) -> np.ndarray:
        """The semantic mask as (H, W) uint8 label ids."""
        self._require_mask(self.semantic_mask_path, "semantic mask")
        mask = _read_image(self.semantic_mask_path, cv2.IMREAD_UNCHANGED, "semantic mask", self.token)
        if mask.ndim != 2 or mask.dtype != np.uint8:
            raise DatasetError(
                f"semantic mask must be single-channel uint8, got {mask.dtype} shape {mask.shape}",
                path=self.semantic_mask_path,
                record=self.token,
            )
        return self._check_size(mask, self.semantic_mask_path, "semantic mask")

    def load_instance(self) -> np.ndarray:
        """The instance mask as (H, W) uint16 ids (class * 1000 + index, 0 = none)."""
        self._require_mask(self.instance_mask_path, "instance mask")
        mask = _read_image(self.instance_mask_path, cv2.IMREAD_UNCHANGED, "instance mask", self.token)
        if mask.ndim != 2 or mask.dtype != np.uint16:
            raise DatasetError(
                f"instance mask must be single-channel uint16, got {mask.dtype} shape {mask.shape}",
                path=self.instance_mask_path,
                record=self.token,
            )
        return self._check_size(mask, self.instance_mask_path, "instance mask")


@dataclass(frozen=True, eq=False)
class Frame:
    """One sample (key frame): its time and the key-frame image of each camera that has one."""

    token: str
    """sample token."""
    timestamp_us: int
    """Sample time in microseconds."""
    images: dict[str, CameraImage]
    """Key-frame camera images by channel."""


@dataclass(frozen=True, eq=False)
class ImuSeries:
    """IMU messages (`ms_imu`) in time order."""

    utime: np.ndarray
    """(N,) int64 microseconds."""
    linear_accel: np.ndarray
    """(N, 3) specific force in the ego frame, m/s^2."""
    rotation_rate: np.ndarray
    """(N, 3) angular velocity in the ego frame, rad/s."""
    q: np.ndarray
    """(N, 4) the IMU's own attitude estimate [w, x, y, z]."""

    def __post_init__(self) -> None:
        utime = _frozen_array(self.utime, (-1,), "utime", np.int64)
        n = len(utime)
        object.__setattr__(self, "utime", utime)
        object.__setattr__(self, "linear_accel", _frozen_array(self.linear_accel, (n, 3), "linear_accel"))
        object.__setattr__(self, "rotation_rate", _frozen_array(self.rotation_rate, (n, 3), "rotation_rate"))
        object.__setattr__(self, "q", _frozen_array(self.q, (n, 4), "q"))


@dataclass(frozen=True, eq=False)
class WheelSeries:
    """Wheel speed messages (`zoe_veh_info`) in time order."""

    utime: np.ndarray
    """(N,) int64 microseconds."""
    speed_rpm: np.ndarray
    """(N, 4) wheel speeds in rpm, columns FL, FR, RL, RR (radius: schema.WHEEL_RADIUS_M)."""

    def __post_init__(self) -> None:
        utime = _frozen_array(self.utime, (-1,), "utime", np.int64)
        object.__setattr__(self, "utime", utime)
        object.__setattr__(self, "speed_rpm", _frozen_array(self.speed_rpm, (len(utime), 4), "speed_rpm"))


@dataclass(frozen=True, eq=False)
class GnssSeries:
    """GNSS fixes (`gnss`, a CAMA addition to the CAN bus files) in time order."""

    utime: np.ndarray
    """(N,) int64 microseconds."""
    pos_m: np.ndarray
    """(N, 3) position in the global frame, metres."""
    std_m: np.ndarray
    """(N, 3) reported 1-sigma [east, north, up], metres."""
    fix: np.ndarray
    """(N,) bool: whether the receiver had a fix."""

    def __post_init__(self) -> None:
        utime = _frozen_array(self.utime, (-1,), "utime", np.int64)
        n = len(utime)
        object.__setattr__(self, "utime", utime)
        object.__setattr__(self, "pos_m", _frozen_array(self.pos_m, (n, 3), "pos_m"))
        object.__setattr__(self, "std_m", _frozen_array(self.std_m, (n, 3), "std_m"))
        object.__setattr__(self, "fix", _frozen_array(self.fix, (n,), "fix", np.bool_))


@dataclass(frozen=True, eq=False)
class CanData:
    """CAN bus data of one scene; each series is None when its file is absent."""

    imu: ImuSeries | None = None
    wheel: WheelSeries | None = None
    gnss: GnssSeries | None = None


@dataclass(frozen=True, eq=False)
class Scene:
    """One recorded clip: its samples in time order, every camera image per channel, and its CAN data."""

    token: str
    """scene token."""
    name: str
    """Scene name, e.g. `scene-0061` (also names its CAN files)."""
    description: str
    """Free text; nuScenes marks night and rain here."""
    log_token: str
    """The log the scene was cut from."""
    location: str
    """The log's location, e.g. `singapore-onenorth`."""
    frames: tuple[Frame, ...]
    """Samples (key frames) in time order."""
    images: dict[str, tuple[CameraImage, ...]]
    """All images (key frames and sweeps) per camera channel, in time order."""
    can: CanData = field(default_factory=CanData)
    """IMU, wheel and GNSS series of the scene."""

    @property
    def channels(self) -> tuple[str, ...]:
        """Camera channels that have images in this scene."""
        return tuple(self.images)

    def all_images(self) -> list[CameraImage]:
        """Every camera image of the scene, in time order (ties by channel)."""
        return sorted(
            (im for ims in self.images.values() for im in ims), key=lambda im: (im.timestamp_us, im.channel)
        )


@dataclass(frozen=True, eq=False)
class Dataset:
    """A loaded data set: its scenes, with lookups by token and name."""

    root: Path
    """Data set root (holds the version folder, samples/, sweeps/, can_bus/)."""
    version: str
    """Version folder name, e.g. `v1.0-mini`."""
    scenes: tuple[Scene, ...]
    """Scenes in scene-table order."""
    mask_roots: tuple[Path, ...] = ()
    """The folders the images' masks were looked up in, in order (`cama_pipeline.data.masks`); a worker process
    loading the data set again passes them on."""
    _scene_by_token: dict[str, Scene] = field(init=False, repr=False)
    _scene_by_name: dict[str, Scene] = field(init=False, repr=False)
    _frame_by_token: dict[str, Frame] = field(init=False, repr=False)
    _image_by_token: dict[str, CameraImage] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "_scene_by_token", {s.token: s for s in self.scenes})
        object.__setattr__(self, "_scene_by_name", {s.name: s for s in self.scenes})
        object.__setattr__(self, "_frame_by_token", {f.token: f for s in self.scenes for f in s.frames})
        images = {im.token: im for s in self.scenes for ims in s.images.values() for im in ims}
        object.__setattr__(self, "_image_by_token", images)

    @property
    def version_dir(self) -> Path:
        """Folder of the JSON tables."""
        return self.root / self.version

    def scene(self, token: str) -> Scene:
        """Scene by token."""
        return _lookup(self._scene_by_token, token, "scene token")

    def scene_by_name(self, name: str) -> Scene:
        """Scene by name (e.g. `scene-0061`)."""
        return _lookup(self._scene_by_name, name, "scene name")

    def frame(self, sample_token: str) -> Frame:
        """Frame by sample token."""
        return _lookup(self._frame_by_token, sample_token, "sample token")

    def image(self, sample_data_token: str) -> CameraImage:
        """Camera image by sample_data token."""
        return _lookup(self._image_by_token, sample_data_token, "camera sample_data token")

    def camera_images(self) -> Iterator[CameraImage]:
        """Every camera image of every scene (scene order, then channel, then time)."""
        for scene in self.scenes:
            for images in scene.images.values():
                yield from images


def _lookup(index: dict[str, _T], key: str, what: str) -> _T:
    """index[key], or a KeyError that says what was looked up."""
    try:
        return index[key]
    except KeyError:
        raise KeyError(f"no {what} {key!r} in the data set") from None
