"""Multi-view resynchronisation: group the cameras' images into frames whose times differ from the frame
time (the reference camera's) by at most a limit.

The cameras of a rig fire one after another (the synthetic rig, like nuScenes', spreads a sweep over
42 ms), so a frame is anchored on one reference camera's image and every other camera contributes its
image nearest in time, if that is within the limit. An image joins at most one frame (the nearest);
a camera with no image close enough is left out of that frame and counted.
"""

import logging
from dataclasses import dataclass

import numpy as np

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class ImageStamp:
    """One camera image: its sample_data token, channel and capture time."""

    token: str
    channel: str
    timestamp_us: int


@dataclass(frozen=True)
class SyncedFrame:
    """A resynchronised frame: the reference image's time and one image per camera that fits."""

    timestamp_us: int
    reference_token: str
    images: dict[str, ImageStamp]

    @property
    def time_diff_us(self) -> int:
        """Largest |image time - frame time|."""
        return max(abs(im.timestamp_us - self.timestamp_us) for im in self.images.values())

    @property
    def time_range_us(self) -> int:
        """Latest minus earliest image time in the frame."""
        times = [im.timestamp_us for im in self.images.values()]
        return max(times) - min(times)


def reference_channel(images: list[ImageStamp], wanted: str) -> str:
    """`wanted` if it has images, else the channel with most images (logged)."""
    counts: dict[str, int] = {}
    for im in images:
        counts[im.channel] = counts.get(im.channel, 0) + 1
    if not counts:
        raise ValueError("no camera images to resynchronise")
    if wanted in counts:
        return wanted
    fallback = max(sorted(counts), key=lambda c: counts[c])
    logger.warning("reference camera %s has no images: frames follow %s instead", wanted, fallback)
    return fallback


def resync(images: list[ImageStamp], wanted_reference: str, max_time_diff_us: int) -> list[SyncedFrame]:
    """Frames anchored on the reference channel's images, in time order (see the module docstring)."""
    ref_channel = reference_channel(images, wanted_reference)
    refs = sorted((im for im in images if im.channel == ref_channel), key=lambda im: im.timestamp_us)
    ref_times = np.array([im.timestamp_us for im in refs], dtype=np.int64)
    chosen: list[dict[str, ImageStamp]] = [{ref_channel: im} for im in refs]
    left_out = 0
    for im in images:
        if im.channel == ref_channel:
            continue
        k = int(np.argmin(np.abs(ref_times - im.timestamp_us)))
        diff = abs(int(ref_times[k]) - im.timestamp_us)
        current = chosen[k].get(im.channel)
        if diff > max_time_diff_us:
            left_out += 1
        elif current is None or diff < abs(current.timestamp_us - int(ref_times[k])):
            left_out += current is not None
            chosen[k][im.channel] = im
        else:
            left_out += 1
    if left_out:
        logger.info("resync: %d image(s) fit no frame within %d us", left_out, max_time_diff_us)
    return [
        SyncedFrame(int(ref.timestamp_us), ref.token, dict(sorted(group.items())))
        for ref, group in zip(refs, chosen, strict=True)
    ]
