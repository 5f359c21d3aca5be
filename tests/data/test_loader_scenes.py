"""`load_dataset(scenes=...)` reads only the named scenes (what a stage of a large data set needs) and gives them
exactly as a whole load does; a name the data set lacks is an error naming scene.json and the names it has."""

from pathlib import Path

import numpy as np
import pytest

from cama_pipeline.data import Dataset, DatasetError, Scene, load_dataset
from tests.conftest import GeneratedSite
from tests.data.nuscenes_fixture import NuScenesFixture, write_nuscenes_fixture


def scene_facts(scene: Scene) -> tuple[object, ...]:
    """What a stage reads of a scene: frames, images with their poses, calibrations and masks, CAN data."""
    images = [
        (
            im.token,
            im.channel,
            im.timestamp_us,
            im.is_key_frame,
            im.path,
            tuple(np.round(im.global_from_ego.matrix().ravel(), 12)),
            im.calibration.token,
            im.semantic_mask_path,
        )
        for im in scene.all_images()
    ]
    frames = [(f.token, f.timestamp_us, sorted(im.token for im in f.images.values())) for f in scene.frames]
    wheel = scene.can.wheel
    return (scene.token, scene.location, frames, images, None if wheel is None else wheel.utime.tolist())


@pytest.fixture(scope="module")
def whole(tiny_site: GeneratedSite) -> Dataset:
    return load_dataset(tiny_site.result.out_dir / "nuscenes")


def test_each_scene_alone_is_the_whole_load_s_scene(tiny_site: GeneratedSite, whole: Dataset) -> None:
    root = tiny_site.result.out_dir / "nuscenes"
    assert len(whole.scenes) >= 2
    for scene in whole.scenes:
        alone = load_dataset(root, scenes=[scene.name])
        assert [s.name for s in alone.scenes] == [scene.name]
        assert scene_facts(alone.scenes[0]) == scene_facts(scene)
        other = next(s for s in whole.scenes if s.name != scene.name)
        with pytest.raises(KeyError):
            alone.image(other.frames[0].images["CAM_FRONT"].token)


def test_several_scenes_keep_the_data_set_s_order(tiny_site: GeneratedSite, whole: Dataset) -> None:
    names = [s.name for s in whole.scenes]
    chosen = load_dataset(tiny_site.result.out_dir / "nuscenes", scenes=list(reversed(names[:2])))
    assert [s.name for s in chosen.scenes] == names[:2]


def test_an_unknown_scene_is_named_with_the_known_ones(tiny_site: GeneratedSite, whole: Dataset) -> None:
    with pytest.raises(DatasetError) as caught:
        load_dataset(tiny_site.result.out_dir / "nuscenes", scenes=[whole.scenes[0].name, "scene-9999"])
    message = str(caught.value)
    assert "scene.json" in message and "'scene-9999'" in message and whole.scenes[0].name in message
    assert f"the data set has {len(whole.scenes)} scenes" in message


@pytest.fixture()
def fixture(tmp_path: Path) -> NuScenesFixture:
    return write_nuscenes_fixture(tmp_path / "ds")


def test_lidar_records_are_not_checked(fixture: NuScenesFixture) -> None:
    """A broken lidar record does not stop the load: the loader keeps and checks camera records only."""
    records = fixture.read_table("sample_data")
    lidar = next(r for r in records if "LIDAR" in r["calibrated_sensor_token"])
    lidar.update({"ego_pose_token": "no-such-pose", "timestamp": "soon"})
    fixture.write_table("sample_data", records)
    dataset = load_dataset(fixture.root)
    assert sum(1 for _ in dataset.camera_images()) == 36


def test_a_camera_record_naming_no_known_sensor_is_still_an_error(fixture: NuScenesFixture) -> None:
    token = "sd-CAM_FRONT-1-0"
    fixture.edit_record("sample_data", token, lambda r: r.update({"calibrated_sensor_token": "cs-unknown"}))
    with pytest.raises(DatasetError, match=rf"sample_data\.json: record '{token}'.*cs-unknown"):
        load_dataset(fixture.root)


def test_a_scene_subset_still_checks_its_own_records(fixture: NuScenesFixture) -> None:
    fixture.edit_record("sample_data", "sd-CAM_BACK-0-1", lambda r: r.update({"timestamp": "soon"}))
    with pytest.raises(DatasetError, match=r"'sd-CAM_BACK-0-1', field 'timestamp'"):
        load_dataset(fixture.root, scenes=[fixture.scene_name])


def test_a_token_of_the_wrong_type_is_named_not_a_crash(fixture: NuScenesFixture) -> None:
    token = "sd-CAM_FRONT-1-0"
    fixture.edit_record(
        "sample_data", token, lambda r: r.update({"calibrated_sensor_token": ["cs-CAM_FRONT"]})
    )
    with pytest.raises(
        DatasetError, match=rf"sample_data\.json: record '{token}', field 'calibrated_sensor_token'"
    ):
        load_dataset(fixture.root)
