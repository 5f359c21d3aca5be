"""Load a nuScenes-layout data set (real nuScenes or our synthetic one) into the typed model, validated."""

import logging
import math
import os
from collections import defaultdict
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from cama_pipeline.data.errors import DatasetError
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
from cama_pipeline.data.schema import (
    CAMERA_MODALITY,
    CAN_DIR,
    GNSS_FIELDS,
    GNSS_MESSAGE,
    IMU_FIELDS,
    IMU_MESSAGE,
    INSTANCE_DIR,
    SEMANTIC_DIR,
    WHEEL_FIELDS,
    WHEEL_MESSAGE,
    can_file_name,
    mask_relpath,
)
from cama_pipeline.data.selection import read_camera_tables
from cama_pipeline.data.tables import Record, Table, read_records, table_path

logger = logging.getLogger(__name__)

TOKEN_LINKS: tuple[tuple[str, str, str, bool], ...] = (
    ("scene", "log_token", "log", False),
    ("scene", "first_sample_token", "sample", False),
    ("scene", "last_sample_token", "sample", False),
    ("sample", "scene_token", "scene", False),
    ("sample", "prev", "sample", True),
    ("sample", "next", "sample", True),
    ("sample_data", "sample_token", "sample", False),
    ("sample_data", "ego_pose_token", "ego_pose", False),
    ("sample_data", "calibrated_sensor_token", "calibrated_sensor", False),
    ("sample_data", "prev", "sample_data", True),
    ("sample_data", "next", "sample_data", True),
    ("calibrated_sensor", "sensor_token", "sensor", False),
)
"""(table, field, target table, may be empty): every token field the loader checks resolves."""

_S = TypeVar("_S")


def find_version(root: Path) -> str:
    """Name of the single subfolder of `root` holding `scene.json` (e.g. `v1.0-mini`); else a DatasetError."""
    root = Path(root)
    if not root.is_dir():
        raise DatasetError("data set root is not a folder", path=root)
    subdirs = sorted(p.name for p in root.iterdir() if p.is_dir())
    versions = [name for name in subdirs if (root / name / "scene.json").is_file()]
    if len(versions) == 1:
        return versions[0]
    if not versions:
        raise DatasetError(
            f"no version folder with scene.json; subfolders found: {subdirs or 'none'}", path=root
        )
    raise DatasetError(f"several version folders with scene.json: {versions}; pass version=", path=root)


def load_dataset(
    root: Path,
    version: str | None = None,
    *,
    check_files: bool = True,
    mask_roots: Sequence[Path] | None = None,
    scenes: Sequence[str] | None = None,
) -> Dataset:
    """Read and validate the tables, CAN files and image paths of a data set (images are not decoded).

    `version` is the table folder under `root` (found automatically when None). `check_files=False`
    skips the per-image existence check (e.g. for a partial download); masks are looked up either way.
    `mask_roots` are the folders the masks are looked up in, in order, each laid out like a data set's masks
    (`cama_pipeline.data.masks.mask_roots` resolves a `--masks` choice to them); None: the data set's own.
    `scenes` (names) loads only those scenes, reading only their records of the large tables
    (`cama_pipeline.data.selection`); a prev/next link that leaves them is then not checked. None: every scene.
    """
    root = Path(root).absolute()
    if not root.is_dir():
        raise DatasetError("data set root is not a folder", path=root)
    if version is None:
        version = find_version(root)
    version_dir = root / version
    if not (version_dir / "scene.json").is_file():
        found = sorted(p.name for p in root.iterdir() if p.is_dir())
        raise DatasetError(
            f"version folder {version!r} has no scene.json; subfolders found: {found}", path=root
        )
    tables = read_camera_tables(version_dir, scenes)
    roots = (root,) if mask_roots is None else tuple(Path(r).absolute() for r in mask_roots)
    loader = _Loader(root, version_dir, tables, check_files, roots, subset=scenes is not None)
    loader.check_links()
    dataset = loader.build(version)
    n_images = sum(1 for _ in dataset.camera_images())
    logger.info("loaded %s: %d scenes, %d camera images", version_dir, len(dataset.scenes), n_images)
    return dataset


class _Loader:
    """Turns validated tables into the model; every error names table, token and field."""

    def __init__(
        self,
        root: Path,
        version_dir: Path,
        tables: dict[str, Table],
        check_files: bool,
        mask_roots: tuple[Path, ...],
        subset: bool = False,
    ) -> None:
        self.root = root
        self.subset = subset
        """Whether only some scenes were read: an unresolved prev/next link may then lead out of them."""
        self.root_str = str(root)
        self.version_dir = version_dir
        self.tables = tables
        self.check_files = check_files
        self.mask_roots = mask_roots
        self.mask_dirs = {
            kind: [str(r) for r in mask_roots if (r / kind).is_dir()] for kind in (SEMANTIC_DIR, INSTANCE_DIR)
        }
        """Per mask kind, the roots that have its folder (the others are not listed image by image)."""
        self.mask_files = _FolderListings()
        self.calibrations: dict[str, CameraCalibration] = {}

    def error(self, table: str, token: str, field: str, detail: str) -> DatasetError:
        """A DatasetError located at one field of one record of a table."""
        return DatasetError(detail, path=table_path(self.version_dir, table), record=token, field=field)

    def check_links(self) -> None:
        """Every token field of TOKEN_LINKS names an existing record of its target table."""
        for table, field, target, optional in TOKEN_LINKS:
            targets = self.tables[target]
            for token, record in self.tables[table].items():
                value = record[field]
                if optional and (value == "" or (self.subset and isinstance(value, str))):
                    continue
                if not isinstance(value, str) or value not in targets:
                    raise self.error(table, token, field, f"token {value!r} not found in {target}.json")

    def build(self, version: str) -> Dataset:
        """All scenes, with frames, camera images and CAN data."""
        images = self.camera_images()
        by_sample: dict[str, list[CameraImage]] = defaultdict(list)
        for image in images:
            by_sample[image.sample_token].append(image)
        samples_by_scene: dict[str, list[str]] = defaultdict(list)
        for token, sample in self.tables["sample"].items():
            samples_by_scene[sample["scene_token"]].append(token)
        scenes = tuple(
            self.scene(token, samples_by_scene[token], by_sample) for token in self.tables["scene"]
        )
        names: dict[str, str] = {}
        for scene in scenes:
            if scene.name in names:
                raise self.error(
                    "scene", scene.token, "name", f"name {scene.name!r} also used by {names[scene.name]}"
                )
            names[scene.name] = scene.token
        return Dataset(root=self.root, version=version, scenes=scenes, mask_roots=self.mask_roots)

    # -- values ---------------------------------------------------------------------------------------------

    def integer(self, table: str, token: str, field: str) -> int:
        """An integer field (timestamps, sizes); booleans and floats are rejected."""
        value = self.tables[table][token][field]
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.error(table, token, field, f"expected an integer, got {value!r}")
        return value

    def vector(self, table: str, token: str, field: str, length: int) -> list[float]:
        """A list of `length` finite numbers."""
        value = self.tables[table][token][field]
        if (
            not isinstance(value, list)
            or len(value) != length
            or not all(
                isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) for v in value
            )
        ):
            raise self.error(table, token, field, f"expected {length} finite numbers, got {value!r}")
        return value

    def pose(self, table: str, token: str) -> Pose:
        """A Pose from the `translation` and `rotation` fields of a record."""
        translation = self.vector(table, token, "translation", 3)
        rotation = self.vector(table, token, "rotation", 4)
        if math.hypot(*rotation) < 1e-9:
            raise self.error(table, token, "rotation", f"quaternion {rotation} has zero norm")
        return Pose(np.array(translation), np.array(rotation))

    def string(self, table: str, token: str, field: str) -> str:
        """A string field."""
        value = self.tables[table][token][field]
        if not isinstance(value, str):
            raise self.error(table, token, field, f"expected a string, got {value!r}")
        return value

    # -- cameras --------------------------------------------------------------------------------------------

    def camera_channels(self) -> dict[str, str]:
        """calibrated_sensor token -> channel, for camera sensors only."""
        cameras = {}
        for token in self.tables["sensor"]:
            if self.string("sensor", token, "modality") == CAMERA_MODALITY:
                cameras[token] = self.string("sensor", token, "channel")
        return {
            token: cameras[record["sensor_token"]]
            for token, record in self.tables["calibrated_sensor"].items()
            if record["sensor_token"] in cameras
        }

    def calibration(self, token: str, channel: str, sample_data_token: str) -> CameraCalibration:
        """Camera calibration of a calibrated_sensor, sized by the sample_data using it (sizes must agree)."""
        width = self.integer("sample_data", sample_data_token, "width")
        height = self.integer("sample_data", sample_data_token, "height")
        if width <= 0 or height <= 0:
            raise self.error(
                "sample_data", sample_data_token, "width", f"image size {width}x{height} not positive"
            )
        known = self.calibrations.get(token)
        if known is not None:
            if (known.width, known.height) != (width, height):
                raise self.error(
                    "sample_data",
                    sample_data_token,
                    "width",
                    f"image size {width}x{height} differs from {known.width}x{known.height} of other images "
                    f"of calibrated_sensor {token!r}",
                )
            return known
        calibration = CameraCalibration(
            token=token,
            channel=channel,
            ego_from_cam=self.pose("calibrated_sensor", token),
            intrinsic=self.intrinsic(token),
            width=width,
            height=height,
        )
        self.calibrations[token] = calibration
        return calibration

    def intrinsic(self, token: str) -> np.ndarray:
        """The 3x3 `camera_intrinsic` of a calibrated_sensor, finite numbers."""
        rows = self.tables["calibrated_sensor"][token]["camera_intrinsic"]
        if (
            not isinstance(rows, list)
            or len(rows) != 3
            or not all(isinstance(r, list) and len(r) == 3 and _all_numbers(r) for r in rows)
            or not all(math.isfinite(v) for r in rows for v in r)
        ):
            raise self.error(
                "calibrated_sensor",
                token,
                "camera_intrinsic",
                f"expected a 3x3 matrix of finite numbers, got {rows!r}",
            )
        return np.array(rows, dtype=np.float64)

    def camera_images(self) -> list[CameraImage]:
        """Every camera sample_data as a CameraImage (other modalities are skipped)."""
        channels = self.camera_channels()
        images = []
        for token, record in self.tables["sample_data"].items():
            channel = channels.get(record["calibrated_sensor_token"])
            if channel is not None:
                images.append(self.camera_image(token, record, channel))
        return images

    def camera_image(self, token: str, record: Record, channel: str) -> CameraImage:
        """One camera sample_data record as a CameraImage; its image file must exist."""
        filename = self.string("sample_data", token, "filename")
        if not filename or os.path.isabs(filename):
            raise self.error(
                "sample_data", token, "filename", f"expected a path relative to the root, got {filename!r}"
            )
        path = os.path.join(self.root_str, filename)
        if self.check_files and not os.path.exists(path):
            listed_in = table_path(self.version_dir, "sample_data")
            detail = f"image file not found (listed by this sample_data record of {listed_in})"
            raise DatasetError(detail, path=path, record=token, field="filename")
        is_key_frame = record["is_key_frame"]
        if not isinstance(is_key_frame, bool):
            raise self.error(
                "sample_data", token, "is_key_frame", f"expected true or false, got {is_key_frame!r}"
            )
        return CameraImage(
            token=token,
            sample_token=record["sample_token"],
            channel=channel,
            timestamp_us=self.integer("sample_data", token, "timestamp"),
            is_key_frame=is_key_frame,
            path=Path(path),
            global_from_ego=self.pose("ego_pose", record["ego_pose_token"]),
            calibration=self.calibration(record["calibrated_sensor_token"], channel, token),
            semantic_mask_path=self.mask_path(SEMANTIC_DIR, filename),
            instance_mask_path=self.mask_path(INSTANCE_DIR, filename),
        )

    def mask_path(self, mask_dir: str, filename: str) -> Path | None:
        """Absolute path of an image's mask in the first mask root that holds it; None when none does."""
        relative = mask_relpath(mask_dir, filename)
        for root in self.mask_dirs[mask_dir]:
            path = os.path.join(root, relative)
            if self.mask_files.exists(path):
                return Path(path)
        return None

    # -- scenes ---------------------------------------------------------------------------------------------

    def frame(self, token: str, images: list[CameraImage]) -> Frame:
        """One sample with its key-frame images by channel (at most one per channel)."""
        by_channel: dict[str, CameraImage] = {}
        for image in images:
            if not image.is_key_frame:
                continue
            if image.channel in by_channel:
                raise self.error(
                    "sample_data",
                    image.token,
                    "sample_token",
                    f"second key-frame {image.channel} image of sample {token!r} "
                    f"(the first is {by_channel[image.channel].token!r})",
                )
            by_channel[image.channel] = image
        return Frame(token=token, timestamp_us=self.integer("sample", token, "timestamp"), images=by_channel)

    def scene(self, token: str, sample_tokens: list[str], by_sample: dict[str, list[CameraImage]]) -> Scene:
        """One scene: frames and images sorted by time, the log's location, the CAN data."""
        record = self.tables["scene"][token]
        frames = sorted(
            (self.frame(s, by_sample.get(s, [])) for s in sample_tokens),
            key=lambda f: (f.timestamp_us, f.token),
        )
        self.check_scene_samples(token, [f.token for f in frames])
        per_channel: dict[str, list[CameraImage]] = defaultdict(list)
        for sample in sample_tokens:
            for image in by_sample.get(sample, []):
                per_channel[image.channel].append(image)
        images = {
            channel: tuple(sorted(ims, key=lambda im: (im.timestamp_us, im.token)))
            for channel, ims in sorted(per_channel.items())
        }
        name = self.string("scene", token, "name")
        return Scene(
            token=token,
            name=name,
            description=self.string("scene", token, "description"),
            log_token=record["log_token"],
            location=self.string("log", record["log_token"], "location"),
            frames=tuple(frames),
            images=images,
            can=load_can(self.root, name),
        )

    def check_scene_samples(self, token: str, ordered: list[str]) -> None:
        """The scene's first/last sample tokens and sample count agree with the samples pointing to it."""
        count = self.integer("scene", token, "nbr_samples")
        if not ordered:
            raise self.error(
                "scene", token, "first_sample_token", "no record of sample.json names this scene"
            )
        if count != len(ordered):
            raise self.error(
                "scene", token, "nbr_samples", f"says {count}, but {len(ordered)} samples name this scene"
            )
        for field, expected in (("first_sample_token", ordered[:1]), ("last_sample_token", ordered[-1:])):
            value = self.tables["scene"][token][field]
            if [value] != expected:
                owner = self.tables["sample"][value]["scene_token"]
                which = "earliest" if field == "first_sample_token" else "latest"
                detail = (
                    f"sample {value!r} belongs to scene {owner!r}" if owner != token else "out of time order"
                )
                raise self.error(
                    "scene", token, field, f"{detail}; the {which} of its samples is {expected[0]!r}"
                )


class _FolderListings:
    """Answers "does this file exist?" by listing each folder once, not one system call per file."""

    def __init__(self) -> None:
        self._names: dict[str, frozenset[str]] = {}

    def exists(self, path: str) -> bool:
        """Whether `path` is an entry of its folder (False when the folder cannot be listed)."""
        folder, name = os.path.split(path)
        names = self._names.get(folder)
        if names is None:
            try:
                names = frozenset(os.listdir(folder))
            except OSError:
                names = frozenset()
            self._names[folder] = names
        return name in names


def _all_numbers(values: Any) -> bool:
    """Whether every value is an int or float (not a bool)."""
    return all(isinstance(v, int | float) and not isinstance(v, bool) for v in values)


# -- CAN bus ------------------------------------------------------------------------------------------------


def load_can(root: Path, scene_name: str) -> CanData:
    """The IMU, wheel and GNSS series of a scene from `<root>/can_bus/`; absent files give None."""
    can_dir = Path(root) / CAN_DIR
    return CanData(
        imu=_read_can(can_dir / can_file_name(scene_name, IMU_MESSAGE), IMU_FIELDS, _imu_series),
        wheel=_read_can(can_dir / can_file_name(scene_name, WHEEL_MESSAGE), WHEEL_FIELDS, _wheel_series),
        gnss=_read_can(can_dir / can_file_name(scene_name, GNSS_MESSAGE), GNSS_FIELDS, _gnss_series),
    )


def _read_can(path: Path, fields: tuple[str, ...], build: Callable[[Path, list[Record]], _S]) -> _S | None:
    """Read one CAN message file (None when absent), sort it by utime and build its series."""
    if not path.is_file():
        logger.debug("no CAN file %s", path)
        return None
    records = read_records(path, fields)
    utime = [r["utime"] for r in records]
    for index, value in enumerate(utime):
        if isinstance(value, bool) or not isinstance(value, int):
            raise DatasetError(
                f"expected an integer, got {value!r}", path=path, record=f"#{index}", field="utime"
            )
    if any(b < a for a, b in zip(utime, utime[1:], strict=False)):
        logger.warning("%s is not sorted by utime: sorting it", path)
        records = sorted(records, key=lambda r: r["utime"])
    return build(path, records)


def _float_column(path: Path, records: list[Record], field: str, width: int) -> np.ndarray:
    """Field `field` of every record as an (N, width) float array (width 0: (N,)); each value finite."""
    shape = (len(records), width) if width else (len(records),)
    if not records:
        return np.zeros(shape)
    try:
        values = np.array([r[field] for r in records], dtype=np.float64)
        if values.shape == shape and np.all(np.isfinite(values)):
            return values
    except (TypeError, ValueError):
        pass
    want = f"a list of {width} finite numbers" if width else "a finite number"
    for index, record in enumerate(records):
        value = record[field]
        items = value if width and isinstance(value, list) else [value]
        if len(items) != max(width, 1) or not _all_numbers(items) or not all(math.isfinite(v) for v in items):
            raise DatasetError(f"expected {want}, got {value!r}", path=path, record=f"#{index}", field=field)
    raise DatasetError(f"values do not form an array of shape {shape}", path=path, field=field)


def _imu_series(path: Path, records: list[Record]) -> ImuSeries:
    """ImuSeries of ms_imu records."""
    return ImuSeries(
        utime=np.array([r["utime"] for r in records], dtype=np.int64),
        linear_accel=_float_column(path, records, "linear_accel", 3),
        rotation_rate=_float_column(path, records, "rotation_rate", 3),
        q=_float_column(path, records, "q", 4),
    )


def _wheel_series(path: Path, records: list[Record]) -> WheelSeries:
    """WheelSeries of zoe_veh_info records (columns FL, FR, RL, RR)."""
    speeds = [_float_column(path, records, field, 0) for field in WHEEL_FIELDS[1:]]
    return WheelSeries(
        utime=np.array([r["utime"] for r in records], dtype=np.int64),
        speed_rpm=np.stack(speeds, axis=1) if records else np.zeros((0, 4)),
    )


def _gnss_series(path: Path, records: list[Record]) -> GnssSeries:
    """GnssSeries of gnss records; `fix` must be true or false."""
    for index, record in enumerate(records):
        if not isinstance(record["fix"], bool):
            raise DatasetError(
                f"expected true or false, got {record['fix']!r}", path=path, record=f"#{index}", field="fix"
            )
    return GnssSeries(
        utime=np.array([r["utime"] for r in records], dtype=np.int64),
        pos_m=_float_column(path, records, "pos", 3),
        std_m=_float_column(path, records, "std_m", 3),
        fix=np.array([r["fix"] for r in records], dtype=bool),
    )
