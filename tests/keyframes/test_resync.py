"""Multi-view resynchronisation: frames within the time limit, images used once, missing cameras left out."""

import logging

import pytest

from cama_pipeline.keyframes import ImageStamp, resync
from cama_pipeline.synthetic.rig import CAMERA_OFFSET_US

SWEEP_US = 83_333


def rig_images(sweeps: int, offsets: dict[str, int]) -> list[ImageStamp]:
    """Images of a rig firing at 12 Hz with per-camera trigger offsets."""
    return [
        ImageStamp(f"{channel}-{k}", channel, 1_000_000 + k * SWEEP_US + offset)
        for k in range(sweeps)
        for channel, offset in offsets.items()
    ]


def test_generator_rig_resyncs_within_40_ms() -> None:
    images = rig_images(12, CAMERA_OFFSET_US)
    frames = resync(images, "CAM_FRONT", 40_000)
    assert len(frames) == 12
    assert all(len(f.images) == 6 for f in frames)
    # the rig spreads a sweep over 42 ms; to the frame (CAM_FRONT) time no image is further than 33.5 ms
    assert max(f.time_diff_us for f in frames) == 33_500 <= 40_000
    assert max(f.time_range_us for f in frames) == 42_000
    used = [im.token for f in frames for im in f.images.values()]
    assert len(used) == len(set(used)) == len(images)


def test_camera_too_far_in_time_is_left_out(caplog: pytest.LogCaptureFixture) -> None:
    offsets = {"CAM_FRONT": 0, "CAM_BACK": 20_000, "CAM_LATE": 41_000}
    with caplog.at_level(logging.INFO):
        frames = resync(rig_images(5, offsets), "CAM_FRONT", 40_000)
    assert all(set(f.images) == {"CAM_FRONT", "CAM_BACK"} for f in frames)
    assert "5 image(s) fit no frame" in caplog.text


def test_nearest_image_wins_when_two_compete() -> None:
    images = [
        ImageStamp("f", "CAM_FRONT", 100_000),
        ImageStamp("b1", "CAM_BACK", 70_000),
        ImageStamp("b2", "CAM_BACK", 110_000),
    ]
    (frame,) = resync(images, "CAM_FRONT", 40_000)
    assert frame.images["CAM_BACK"].token == "b2"


def test_missing_reference_channel_falls_back(caplog: pytest.LogCaptureFixture) -> None:
    with caplog.at_level(logging.WARNING):
        frames = resync(rig_images(3, {"CAM_BACK": 0, "CAM_FRONT_LEFT": 5_000}), "CAM_FRONT", 40_000)
    assert "has no images" in caplog.text
    assert len(frames) == 3


def test_no_images_is_an_error() -> None:
    with pytest.raises(ValueError, match="no camera images"):
        resync([], "CAM_FRONT", 40_000)
