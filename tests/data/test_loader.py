"""Loader tests on hand-written nuScenes-layout data sets: good data round-trips, bad data names its fault."""

import dataclasses
import json
import math
import random
import shutil
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from cama_pipeline.data import (
    DatasetError,
    Pose,
    find_version,
    load_dataset,
    read_table,
)
from cama_pipeline.data.schema import (
    CAMERA_CHANNELS,
    CAN_DIR,
    GNSS_MESSAGE,
    IMU_MESSAGE,
    OPTIONAL_TABLES,
    REQUIRED_TABLES,
    SEMANTIC_DIR,
    WHEEL_MESSAGE,
)
from cama_pipeline.semantics import INSTANCE_ID_BASE, Semantic
from tests.data.nuscenes_fixture import (
    CAMERA_ROTATION,
    LIDAR_CHANNEL,
    N_GNSS,
    N_IMU,
    N_WHEEL,
    T0_US,
    NuScenesFixture,
    camera_intrinsic,
    camera_translation,
    ego_rotation,
    ego_translation,
    image_timestamp_us,
    sample_data_token,
    write_nuscenes_fixture,
)


@pytest.fixture(scope="session")
def pristine(tmp_path_factory: pytest.TempPathFactory) -> NuScenesFixture:
    """A good one-scene data set: 3 samples, 1 sweep per sample, 6 cameras, masks, CAN and lidar records."""
    return write_nuscenes_fixture(tmp_path_factory.mktemp("pristine") / "nuscenes")


@pytest.fixture
def fixture(pristine: NuScenesFixture, tmp_path: Path) -> NuScenesFixture:
    """A private copy of the good data set to break: tables and CAN files copied, image folders linked.

    Linking keeps each test to a few files; tests that change image files write their own data set.
    """
    root = tmp_path / "nuscenes"
    root.mkdir()
    for entry in pristine.root.iterdir():
        if entry.name in (pristine.version, CAN_DIR):
            shutil.copytree(entry, root / entry.name)
        else:
            (root / entry.name).symlink_to(entry, target_is_directory=True)
    return dataclasses.replace(pristine, root=root)


def load_error(fixture: NuScenesFixture) -> str:
    """Load the fixture, expecting a DatasetError; return its message."""
    with pytest.raises(DatasetError) as info:
        load_dataset(fixture.root)
    return str(info.value)


# -- good data ----------------------------------------------------------------------------------------------


def test_good_dataset_loads_scene_and_frames(fixture: NuScenesFixture) -> None:
    dataset = load_dataset(fixture.root)
    assert dataset.version == fixture.version
    assert dataset.root == fixture.root.absolute()
    assert [s.name for s in dataset.scenes] == [fixture.scene_name]
    scene = dataset.scene(fixture.scene_token)
    assert dataset.scene_by_name(fixture.scene_name) is scene
    assert scene.location == "fixture-town"
    assert scene.description == "fixture scene, day"
    assert scene.log_token == "log-1"
    assert [f.token for f in scene.frames] == list(fixture.sample_tokens)
    assert [f.timestamp_us for f in scene.frames] == [T0_US + i * 500_000 for i in range(3)]
    for i, frame in enumerate(scene.frames):
        assert set(frame.images) == set(CAMERA_CHANNELS)
        for j, channel in enumerate(CAMERA_CHANNELS):
            image = frame.images[channel]
            assert image.is_key_frame
            assert image.token == sample_data_token(channel, i)
            assert image.timestamp_us == image_timestamp_us(j, i, 0, fixture.sweeps_per_sample)
        assert dataset.frame(frame.token) is frame


def test_good_dataset_round_trips_images_poses_and_calibration(fixture: NuScenesFixture) -> None:
    scene = load_dataset(fixture.root).scenes[0]
    assert scene.channels == tuple(sorted(CAMERA_CHANNELS))
    for j, channel in enumerate(CAMERA_CHANNELS):
        images = scene.images[channel]
        assert len(images) == 3 * (1 + fixture.sweeps_per_sample)
        times = [im.timestamp_us for im in images]
        assert times == sorted(times)
        assert [im.is_key_frame for im in images] == [True, False] * 3
        for image in images:
            assert image.path.is_absolute() and image.path.is_file()
            assert image.path.parent.name == channel
            assert image.path.parent.parent.name == ("samples" if image.is_key_frame else "sweeps")
            np.testing.assert_allclose(image.global_from_ego.translation, ego_translation(image.timestamp_us))
            np.testing.assert_allclose(image.global_from_ego.rotation, ego_rotation(image.timestamp_us))
        calibration = images[0].calibration
        assert calibration.channel == channel
        assert (calibration.width, calibration.height) == (fixture.width, fixture.height)
        np.testing.assert_allclose(calibration.intrinsic, camera_intrinsic(j, fixture.width, fixture.height))
        np.testing.assert_allclose(calibration.ego_from_cam.translation, camera_translation(j))
        np.testing.assert_allclose(calibration.ego_from_cam.rotation, CAMERA_ROTATION)
        assert all(im.calibration is calibration for im in images)
    all_times = [im.timestamp_us for im in scene.all_images()]
    assert all_times == sorted(all_times) and len(all_times) == 6 * 6


def test_non_camera_sample_data_is_ignored(fixture: NuScenesFixture) -> None:
    dataset = load_dataset(fixture.root)
    assert LIDAR_CHANNEL not in dataset.scenes[0].images
    assert sum(1 for _ in dataset.camera_images()) == 36
    with pytest.raises(KeyError, match="sd-LIDAR_TOP-0-0"):
        dataset.image(sample_data_token(LIDAR_CHANNEL, 0))


def test_images_and_masks_load_lazily(fixture: NuScenesFixture) -> None:
    dataset = load_dataset(fixture.root)
    image = dataset.image(sample_data_token("CAM_BACK", 1))
    rgb = image.load_rgb()
    assert rgb.shape == (fixture.height, fixture.width, 3) and rgb.dtype == np.uint8
    np.testing.assert_allclose(rgb[4, 8], [10 * CAMERA_CHANNELS.index("CAM_BACK"), 200, 0], atol=6)
    semantic = image.load_semantic()
    assert semantic.dtype == np.uint8 and semantic.shape == (fixture.height, fixture.width)
    assert semantic[0, 0] == Semantic.SKY and semantic[3, 3] == Semantic.ROAD
    instance = image.load_instance()
    assert instance.dtype == np.uint16
    assert instance[-1, 0] == Semantic.LANE_MARKING * INSTANCE_ID_BASE + 1 and instance[0, 0] == 0


def test_can_data_arrays(fixture: NuScenesFixture) -> None:
    can = load_dataset(fixture.root).scenes[0].can
    assert can.imu is not None and can.wheel is not None and can.gnss is not None
    assert can.imu.utime.shape == (N_IMU,) and can.imu.utime.dtype == np.int64
    assert can.imu.linear_accel.shape == (N_IMU, 3) and can.imu.rotation_rate.shape == (N_IMU, 3)
    assert can.imu.q.shape == (N_IMU, 4)
    assert can.imu.linear_accel[3, 0] == pytest.approx(0.3)
    assert can.wheel.speed_rpm.shape == (N_WHEEL, 4)
    np.testing.assert_allclose(can.wheel.speed_rpm[2], [152.0, 153.0, 154.0, 155.0])
    assert can.gnss.pos_m.shape == (N_GNSS, 3) and can.gnss.std_m.shape == (N_GNSS, 3)
    assert can.gnss.fix.dtype == bool and can.gnss.fix.tolist() == [True, True, False, True]
    assert not can.imu.utime.flags.writeable


def test_order_follows_time_not_file_order(fixture: NuScenesFixture) -> None:
    for name in ("sample", "sample_data", "ego_pose"):
        records = fixture.read_table(name)
        random.Random(0).shuffle(records)
        fixture.write_table(name, records)
    imu = json.loads(fixture.can_path(IMU_MESSAGE).read_text())
    fixture.can_path(IMU_MESSAGE).write_text(json.dumps(imu[::-1]))
    scene = load_dataset(fixture.root).scenes[0]
    assert [f.token for f in scene.frames] == list(fixture.sample_tokens)
    times = [im.timestamp_us for im in scene.images["CAM_FRONT"]]
    assert times == sorted(times)
    assert scene.can.imu is not None and np.all(np.diff(scene.can.imu.utime) > 0)


def test_absent_optional_parts_are_fine(tmp_path: Path) -> None:
    fixture = write_nuscenes_fixture(
        tmp_path, with_optional_tables=False, with_masks=False, with_can=False, with_lidar=False
    )
    scene = load_dataset(fixture.root).scenes[0]
    assert scene.can.imu is None and scene.can.wheel is None and scene.can.gnss is None
    image = scene.frames[0].images["CAM_FRONT"]
    assert image.semantic_mask_path is None and image.instance_mask_path is None
    with pytest.raises(DatasetError, match="no semantic mask"):
        image.load_semantic()
    for name in OPTIONAL_TABLES:
        assert read_table(fixture.version_dir, name) == {}


def test_gnss_file_absent_gives_none(tmp_path: Path) -> None:
    fixture = write_nuscenes_fixture(tmp_path, with_gnss=False)
    can = load_dataset(fixture.root).scenes[0].can
    assert can.gnss is None and can.imu is not None and can.wheel is not None


def test_pose_matrix_inverse_and_composition() -> None:
    yaw = math.pi / 2
    global_from_ego = Pose(np.array([1.0, 2.0, 3.0]), np.array([math.cos(yaw / 2), 0, 0, math.sin(yaw / 2)]))
    matrix = global_from_ego.matrix()
    np.testing.assert_allclose(matrix[:3, :3], [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-12)
    np.testing.assert_allclose(
        global_from_ego.transform_points(np.array([[1.0, 0.0, 0.0]])), [[1.0, 3.0, 3.0]]
    )
    np.testing.assert_allclose((global_from_ego @ global_from_ego.inverse()).matrix(), np.eye(4), atol=1e-12)
    ego_from_cam = Pose(np.array([1.5, 0.0, 1.6]), np.array(CAMERA_ROTATION))
    np.testing.assert_allclose(
        (global_from_ego @ ego_from_cam).matrix(), matrix @ ego_from_cam.matrix(), atol=1e-12
    )
    np.testing.assert_allclose(Pose(np.zeros(3), np.array([2.0, 0, 0, 0])).rotation, [1, 0, 0, 0])
    with pytest.raises(ValueError, match="zero norm"):
        Pose(np.zeros(3), np.zeros(4))


def test_global_from_cam_maps_optical_axis_forward(fixture: NuScenesFixture) -> None:
    image = load_dataset(fixture.root).image(sample_data_token("CAM_FRONT", 0))
    points = image.global_from_cam.transform_points(np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 1.0]]))
    forward = points[1] - points[0]
    yaw = 0.2 * (image.timestamp_us - T0_US) / 1e6
    np.testing.assert_allclose(forward, [math.cos(yaw), math.sin(yaw), 0.0], atol=1e-9)


# -- version detection --------------------------------------------------------------------------------------


def test_version_auto_detection(fixture: NuScenesFixture) -> None:
    (fixture.root / "maps").mkdir()
    assert find_version(fixture.root) == fixture.version
    shutil.copytree(fixture.version_dir, fixture.root / "v1.0-other")
    with pytest.raises(DatasetError, match="several") as info:
        load_dataset(fixture.root)
    assert fixture.version in str(info.value) and "v1.0-other" in str(info.value)
    assert load_dataset(fixture.root, "v1.0-other").version == "v1.0-other"


def test_no_version_folder_lists_what_was_found(tmp_path: Path) -> None:
    (tmp_path / "samples").mkdir()
    (tmp_path / "v1.0-empty").mkdir()
    with pytest.raises(DatasetError, match="no version folder") as info:
        load_dataset(tmp_path)
    assert "samples" in str(info.value) and "v1.0-empty" in str(info.value)
    with pytest.raises(DatasetError, match="v1.0-missing"):
        load_dataset(tmp_path, "v1.0-missing")


# -- bad tables ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", [n for n in REQUIRED_TABLES if n != "scene"])
def test_missing_required_table(fixture: NuScenesFixture, name: str) -> None:
    fixture.table_path(name).unlink()
    message = load_error(fixture)
    assert f"{name}.json" in message and "missing" in message


def test_bad_json_names_file_line_and_column(fixture: NuScenesFixture) -> None:
    text = fixture.table_path("ego_pose").read_text()
    fixture.table_path("ego_pose").write_text(text[: len(text) // 2])
    message = load_error(fixture)
    assert "ego_pose.json" in message and "line" in message and "column" in message


def test_table_not_a_list(fixture: NuScenesFixture) -> None:
    fixture.table_path("log").write_text('{"token": "log-1"}')
    assert "log.json" in load_error(fixture)


def test_missing_field_names_file_record_and_field(fixture: NuScenesFixture) -> None:
    fixture.edit_record("sample", "sample-1", lambda r: r.pop("timestamp"))
    message = load_error(fixture)
    assert "sample.json" in message and "'sample-1'" in message and "'timestamp'" in message


def test_missing_token_names_record_index(fixture: NuScenesFixture) -> None:
    records = fixture.read_table("sensor")
    del records[2]["token"]
    fixture.write_table("sensor", records)
    message = load_error(fixture)
    assert "sensor.json" in message and "#2" in message and "'token'" in message


def test_duplicate_token(fixture: NuScenesFixture) -> None:
    records = fixture.read_table("log")
    fixture.write_table("log", records + records)
    message = load_error(fixture)
    assert "log.json" in message and "duplicate" in message and "'log-1'" in message


BROKEN_LINKS = [
    ("scene", "scene-token-1", "log_token"),
    ("scene", "scene-token-1", "first_sample_token"),
    ("scene", "scene-token-1", "last_sample_token"),
    ("sample", "sample-1", "scene_token"),
    ("sample", "sample-1", "prev"),
    ("sample", "sample-1", "next"),
    ("sample_data", "sd-CAM_FRONT-1-0", "sample_token"),
    ("sample_data", "sd-CAM_FRONT-1-0", "ego_pose_token"),
    ("sample_data", "sd-CAM_FRONT-1-0", "calibrated_sensor_token"),
    ("sample_data", "sd-CAM_FRONT-1-0", "prev"),
    ("sample_data", "sd-CAM_FRONT-1-0", "next"),
    ("calibrated_sensor", "cs-CAM_BACK", "sensor_token"),
]


@pytest.mark.parametrize(("table", "token", "field"), BROKEN_LINKS)
def test_broken_token_link(fixture: NuScenesFixture, table: str, token: str, field: str) -> None:
    fixture.edit_record(table, token, lambda r: r.update({field: "no-such-token"}))
    message = load_error(fixture)
    for part in (f"{table}.json", repr(token), repr(field), "no-such-token"):
        assert part in message


BAD_POSES: list[tuple[str, str, str, Any]] = [
    ("ego_pose", "ep-sd-CAM_FRONT-2-1", "translation", [1.0, float("nan"), 0.0]),
    ("ego_pose", "ep-sd-CAM_FRONT-2-1", "rotation", [1.0, 0.0, float("inf"), 0.0]),
    ("ego_pose", "ep-sd-CAM_FRONT-2-1", "rotation", [1.0, 0.0, 0.0]),
    ("calibrated_sensor", "cs-CAM_FRONT", "rotation", [0.0, 0.0, 0.0, 0.0]),
    ("calibrated_sensor", "cs-CAM_FRONT", "translation", "1 2 3"),
    ("calibrated_sensor", "cs-CAM_FRONT", "camera_intrinsic", [[1.0, 0.0], [0.0, 1.0]]),
    ("calibrated_sensor", "cs-CAM_FRONT", "camera_intrinsic", [[1.0, 0.0, 1.0], [0.0, None, 1.0], [0, 0, 1]]),
]


@pytest.mark.parametrize(("table", "token", "field", "value"), BAD_POSES)
def test_bad_pose_or_calibration(
    fixture: NuScenesFixture, table: str, token: str, field: str, value: Any
) -> None:
    fixture.edit_record(table, token, lambda r: r.update({field: value}))
    message = load_error(fixture)
    for part in (f"{table}.json", repr(token), repr(field)):
        assert part in message


def test_bad_timestamp_type(fixture: NuScenesFixture) -> None:
    fixture.edit_record("sample_data", "sd-CAM_BACK-0-1", lambda r: r.update({"timestamp": "soon"}))
    message = load_error(fixture)
    assert "sample_data.json" in message and "'sd-CAM_BACK-0-1'" in message and "'timestamp'" in message


def test_scene_sample_count_must_match(fixture: NuScenesFixture) -> None:
    fixture.edit_record("scene", fixture.scene_token, lambda r: r.update({"nbr_samples": 5}))
    message = load_error(fixture)
    assert "scene.json" in message and "'nbr_samples'" in message


def test_scene_first_sample_must_be_earliest(fixture: NuScenesFixture) -> None:
    fixture.edit_record("scene", fixture.scene_token, lambda r: r.update({"first_sample_token": "sample-1"}))
    message = load_error(fixture)
    assert "'first_sample_token'" in message and "time order" in message and "'sample-0'" in message


def test_scene_without_samples(fixture: NuScenesFixture) -> None:
    scenes = fixture.read_table("scene")
    fixture.write_table("scene", scenes + [{**scenes[0], "token": "scene-2", "name": "scene-0002"}])
    message = load_error(fixture)
    assert "scene.json" in message and "'scene-2'" in message and "no record of sample.json" in message


def test_duplicate_scene_name(fixture: NuScenesFixture) -> None:
    scenes = fixture.read_table("scene")
    fixture.edit_record("sample", "sample-2", lambda r: r.update({"scene_token": "scene-2", "prev": ""}))
    fixture.edit_record("sample", "sample-1", lambda r: r.update({"next": ""}))
    second = {
        "token": "scene-2",
        "nbr_samples": 1,
        "first_sample_token": "sample-2",
        "last_sample_token": "sample-2",
    }
    scenes[0].update({"nbr_samples": 2, "last_sample_token": "sample-1"})
    fixture.write_table("scene", scenes + [{**scenes[0], **second}])
    message = load_error(fixture)
    assert "scene.json" in message and "'scene-2'" in message and "'name'" in message


# -- bad files ----------------------------------------------------------------------------------------------


def test_missing_image_names_path_and_token(tmp_path: Path) -> None:
    fixture = write_nuscenes_fixture(tmp_path, with_masks=False)
    token = sample_data_token("CAM_FRONT_LEFT", 2, 1)
    filename = next(r["filename"] for r in fixture.read_table("sample_data") if r["token"] == token)
    (fixture.root / filename).unlink()
    message = load_error(fixture)
    assert filename in message and repr(token) in message
    assert load_dataset(fixture.root, check_files=False).image(token).path.name == Path(filename).name


def test_unreadable_image_raises_on_load(tmp_path: Path) -> None:
    fixture = write_nuscenes_fixture(tmp_path)
    image = load_dataset(fixture.root).image(sample_data_token("CAM_FRONT", 0))
    image.path.write_bytes(b"not a jpeg")
    with pytest.raises(DatasetError, match="cannot be decoded") as info:
        image.load_rgb()
    assert str(image.path) in str(info.value)
    assert image.semantic_mask_path is not None
    image.semantic_mask_path.unlink()
    with pytest.raises(DatasetError, match="not found") as info:
        image.load_semantic()
    assert str(fixture.root.absolute() / SEMANTIC_DIR) in str(info.value)


def test_bad_can_json(fixture: NuScenesFixture) -> None:
    fixture.can_path(IMU_MESSAGE).write_text("[{]")
    message = load_error(fixture)
    assert str(fixture.can_path(IMU_MESSAGE)) in message and "line 1" in message


def test_can_missing_field(fixture: NuScenesFixture) -> None:
    records = json.loads(fixture.can_path(WHEEL_MESSAGE).read_text())
    del records[3]["RL_wheel_speed"]
    fixture.can_path(WHEEL_MESSAGE).write_text(json.dumps(records))
    message = load_error(fixture)
    assert (
        str(fixture.can_path(WHEEL_MESSAGE)) in message and "#3" in message and "'RL_wheel_speed'" in message
    )


@pytest.mark.parametrize(
    ("field", "value"), [("pos", [1.0, 2.0]), ("std_m", [1.0, float("nan"), 1.0]), ("fix", 1), ("utime", 1.5)]
)
def test_can_bad_values(fixture: NuScenesFixture, field: str, value: Any) -> None:
    records = json.loads(fixture.can_path(GNSS_MESSAGE).read_text())
    records[1][field] = value
    fixture.can_path(GNSS_MESSAGE).write_text(json.dumps(records))
    message = load_error(fixture)
    assert str(fixture.can_path(GNSS_MESSAGE)) in message and "#1" in message and repr(field) in message


def test_dataset_error_is_a_value_error() -> None:
    error = DatasetError("bad", path="x.json", record="tok", field="f")
    assert isinstance(error, ValueError)
    assert str(error) == "x.json: record 'tok', field 'f': bad"
    assert (error.path, error.record, error.field, error.detail) == (Path("x.json"), "tok", "f", "bad")
