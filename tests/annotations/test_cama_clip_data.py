"""CAMA clip data (`annotations.cama_clip_data`) on the tiny site: attribute.json's sync lists and calibration,
the images' bytes, the lane instance masks in CAMA's ids, missing masks and bad input."""

import dataclasses
import json
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import pytest

from annotations.cama_clip_data import ATTRIBUTE_JSON, SIDECAR_JSON, ClipDataResult, write_clip_data
from annotations.cama_clip_masks import lane_masks_in
from annotations.cama_odometry import CAMERA_NAME_FROM_CHANNEL, timestamp_ms
from cama_pipeline.data import CameraImage, Dataset, load_dataset
from tests.conftest import GeneratedSite

SCENE = "scene-0001"
CHANNEL_FROM_CAMERA = {name: channel for channel, name in CAMERA_NAME_FROM_CHANNEL.items()}


@dataclass(frozen=True)
class Written:
    """One scene's clip data written from the tiny site."""

    dataset: Dataset
    folder: Path
    result: ClipDataResult
    attribute: dict


@pytest.fixture(scope="module")
def dataset(tiny_site: GeneratedSite) -> Dataset:
    return load_dataset(tiny_site.result.out_dir / "nuscenes")


@pytest.fixture(scope="module")
def written(dataset: Dataset, tmp_path_factory: pytest.TempPathFactory) -> Written:
    folder = tmp_path_factory.mktemp("clip") / "all_clips" / SCENE
    result = write_clip_data(folder, dataset, SCENE)
    attribute = json.loads((folder / ATTRIBUTE_JSON).read_text())
    return Written(dataset, folder, result, attribute)


def _image_at(dataset: Dataset, camera: str, ms: int) -> CameraImage:
    """The scene's image of `camera` whose millisecond time is `ms`."""
    images = dataset.scene_by_name(SCENE).images[CHANNEL_FROM_CAMERA[camera]]
    (image,) = [im for im in images if timestamp_ms(im.timestamp_us) == ms]
    return image


def test_sync_lists_are_integer_ms_aligned_with_camera_front(written: Written) -> None:
    sync = written.attribute["sync"]
    scene = written.dataset.scene_by_name(SCENE)
    assert list(sync) == list(written.result.cameras) and set(sync) == set(CAMERA_NAME_FROM_CHANNEL.values())
    front = [timestamp_ms(im.timestamp_us) for im in scene.images["CAM_FRONT"]]
    assert sync["camera_front"] == front and written.result.frames == len(front) > 10
    for camera, times in sync.items():
        assert len(times) == len(front) and all(type(t) is int for t in times)
        own = np.array([im.timestamp_us for im in scene.images[CHANNEL_FROM_CAMERA[camera]]])
        for index, ms in enumerate(times):
            reference_us = scene.images["CAM_FRONT"][index].timestamp_us
            nearest = own[np.argmin(np.abs(own - reference_us))]
            assert ms == timestamp_ms(int(nearest)) and abs(nearest - reference_us) <= 40_000


def test_calibration_is_ego_from_cam_and_intrinsics(written: Written) -> None:
    calibration = written.attribute["calibration"]
    for camera in written.result.cameras:
        ms = written.attribute["sync"][camera][0]
        expected = _image_at(written.dataset, camera, ms).calibration
        np.testing.assert_allclose(
            calibration[f"{camera}_2_chassis"], expected.ego_from_cam.matrix(), atol=1e-12
        )
        np.testing.assert_allclose(calibration[camera]["K"], expected.intrinsic, atol=1e-12)
        assert calibration[camera]["d"] == [0.0] * 8
        assert (calibration[camera]["image_width"], calibration[camera]["image_height"]) == (
            expected.width,
            expected.height,
        )


def test_images_are_the_data_sets_bytes(written: Written) -> None:
    count = 0
    for camera, times in written.attribute["sync"].items():
        files = sorted((written.folder / camera).glob("*.jpg"))
        assert [int(f.stem) for f in files] == sorted(set(times))
        for path in files:
            source = _image_at(written.dataset, camera, int(path.stem)).path
            assert path.read_bytes() == source.read_bytes()
            count += 1
    assert count == written.result.images_written == 6 * written.result.frames


def test_masks_are_16_bit_in_camas_ids(written: Written) -> None:
    lane = curb = crosswalk = 0
    for camera, times in written.attribute["sync"].items():
        for ms in times:
            cama = cv2.imread(str(written.folder / f"lane_ins_{camera}" / f"{ms}.png"), cv2.IMREAD_UNCHANGED)
            ours = _image_at(written.dataset, camera, ms).load_instance()
            assert cama is not None and cama.dtype == np.uint16 and cama.shape == ours.shape
            classes, index = ours // 1000, ours % 1000
            assert np.array_equal(cama[classes == 3], 1000 + index[classes == 3])
            assert np.array_equal(cama[classes == 2], 7000 + index[classes == 2])
            assert not cama[(classes == 4) | (ours == 0)].any()
            lane, curb, crosswalk = (
                lane + (classes == 3).sum(),
                curb + (classes == 2).sum(),
                crosswalk + (classes == 4).sum(),
            )
    assert lane > 0 and curb > 0 and crosswalk > 0  # every branch of the table was exercised
    assert written.result.masks_written == written.result.images_written and written.result.masks_missing == 0
    assert written.result.dropped_mask_instances.get(4, 0) > 0


def test_camas_resize_reads_the_mask(written: Written) -> None:
    """CAMA resizes a mask to 960x540 through its calibration (K, d, size) with nearest-neighbour remapping:
    the values it gets are ids we wrote."""
    camera = "camera_front"
    ms = written.attribute["sync"][camera][3]
    intrinsics = written.attribute["calibration"][camera]
    k = np.asarray(intrinsics["K"])
    scaled = k.copy()
    scaled[0] *= 960 / intrinsics["image_width"]
    scaled[1] *= 540 / intrinsics["image_height"]
    maps = cv2.initUndistortRectifyMap(k, np.asarray(intrinsics["d"]), None, scaled, (960, 540), cv2.CV_32FC1)
    mask = cv2.imread(str(written.folder / f"lane_ins_{camera}" / f"{ms}.png"), cv2.IMREAD_ANYDEPTH)
    assert mask is not None
    resized = cv2.remap(mask, *maps, interpolation=cv2.INTER_NEAREST)
    assert resized.shape == (540, 960) and set(np.unique(resized)) <= set(np.unique(mask))
    assert {int(v) // 1000 for v in np.unique(resized) if v} <= {1, 7} and resized.any()


def test_missing_masks_are_counted_and_listed(written: Written, tmp_path: Path) -> None:
    def no_rear(image: CameraImage) -> Path | None:
        return None if image.channel == "CAM_BACK" else image.instance_mask_path

    result = write_clip_data(tmp_path, written.dataset, SCENE, lane_masks=no_rear, link_images=False)
    assert result.masks_missing == written.result.frames and result.images_linked == 0
    assert not (tmp_path / "lane_ins_camera_rear").exists()
    assert len(list((tmp_path / "lane_ins_camera_front").glob("*.png"))) == written.result.frames
    sidecar = json.loads((tmp_path / SIDECAR_JSON).read_text())
    listed = sidecar["missing_masks"]
    assert {m["camera"] for m in listed} == {"camera_rear"}
    assert [m["timestamp_ms"] for m in listed] == written.attribute["sync"]["camera_rear"]
    assert all(m["image"].split("/")[:2] in (["samples", "CAM_BACK"], ["sweeps", "CAM_BACK"]) for m in listed)


def test_mask_roots_find_the_same_masks(written: Written) -> None:
    lookup = lane_masks_in([written.dataset.root], written.dataset.root)
    images = written.dataset.scene_by_name(SCENE).images["CAM_FRONT_LEFT"]
    assert [lookup(im) for im in images] == [im.instance_mask_path for im in images]
    assert lane_masks_in([written.dataset.root / "nowhere"], written.dataset.root)(images[0]) is None


def test_camera_without_an_image_in_tolerance_drops_the_frame(written: Written, tmp_path: Path) -> None:
    scene = written.dataset.scene_by_name(SCENE)
    rear = scene.images["CAM_BACK"]
    gap = scene.images["CAM_FRONT"][5]
    thinned = dataclasses.replace(scene, images={**scene.images, "CAM_BACK": rear[:5] + rear[6:]})
    dataset = Dataset(root=written.dataset.root, version=written.dataset.version, scenes=(thinned,))
    result = write_clip_data(tmp_path, dataset, SCENE)
    assert [(d.timestamp_ms, d.cameras_without_image) for d in result.dropped_frames] == [
        (timestamp_ms(gap.timestamp_us), ("camera_rear",))
    ]
    sync = json.loads((tmp_path / ATTRIBUTE_JSON).read_text())["sync"]
    assert all(len(times) == written.result.frames - 1 for times in sync.values())
    assert timestamp_ms(gap.timestamp_us) not in sync["camera_front"]
    assert json.loads((tmp_path / SIDECAR_JSON).read_text())["dropped_frames"][0][
        "cameras_without_image"
    ] == ["camera_rear"]


def test_unknown_scene_names_the_known_ones(written: Written, tmp_path: Path) -> None:
    with pytest.raises(ValueError, match=r"'scene-9999'.*scene-0001"):
        write_clip_data(tmp_path, written.dataset, "scene-9999")
    assert not any(tmp_path.iterdir())


def test_bad_mask_names_the_file_and_writes_no_attribute_json(written: Written, tmp_path: Path) -> None:
    bad = tmp_path / "bad.png"
    cv2.imwrite(str(bad), np.zeros((10, 10), dtype=np.uint16))
    out = tmp_path / "out"
    with pytest.raises(ValueError, match=r"bad\.png.*10x10"):
        write_clip_data(out, written.dataset, SCENE, lane_masks=lambda image: bad)
    assert not (out / ATTRIBUTE_JSON).exists()
