"""Camera images and their lane-mask overlays, read only from the paths the data set's tables give, scaled and
kept in a memory LRU with a stable ETag.

A file is served only when its path, symlinks followed, lies inside the data set root (an image) or one of the
mask roots the data set was loaded with (a mask): anything else is refused as an escape (logged) and reads like
an unknown image to the caller. The ETag is a digest of the resolved path, its mtime and size, and the width:
a rewritten file gets a new one.
"""

import colorsys
import hashlib
import logging
import os
import threading
from collections import OrderedDict
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from app.backend.cameras.context import CameraContext
from app.backend.cameras.projection import ImageNotFound

logger = logging.getLogger(__name__)

WIDTHS = (240, 320, 480, 640, 960)
"""The widths an image or mask may be asked at (None: full size); a few, so that the cache stays small."""
TOKEN_PATTERN = r"^[0-9A-Za-z_-]{1,128}$"
"""What an image token may look like (anything else is refused before any lookup)."""
JPEG_QUALITY = 88
MASK_ALPHA = 160
"""Opacity of a lane instance in the overlay (0-255)."""
CACHE_BYTES = 96 * 1024 * 1024
"""The LRU's budget of encoded bytes."""
NO_LANE_MASK = "no lane mask for this image"


class PathEscape(ImageNotFound):
    """A data set path that resolves outside its root (refused, logged)."""


@dataclass(frozen=True)
class Encoded:
    """An encoded image and its ETag (quoted, as sent)."""

    data: bytes
    etag: str
    media_type: str


def contained(path: Path, roots: Sequence[Path], token: str) -> Path:
    """`path` resolved (symlinks followed) when it is a file inside one of `roots` (resolved); PathEscape
    (logged as a refused escape) when it lies outside them, ImageNotFound when it is missing."""
    try:
        resolved = path.resolve(strict=True)
    except (OSError, RuntimeError):
        raise ImageNotFound("the image's file is missing from the data set") from None
    for root in roots:
        if resolved.is_relative_to(root.resolve()) and resolved.is_file():
            return resolved
    logger.warning("refused escape: image %s: %s resolves to %s, outside %s", token, path, resolved, roots)
    raise PathEscape("no camera image with this token in the site's data set")


def image_file(context: CameraContext, token: str) -> Path:
    """The resolved file of a camera image of the site's data set (any camera image, posed or not)."""
    if context.dataset is None:
        raise ImageNotFound("the site has no data set")
    try:
        image = context.dataset.image(token)
    except KeyError:
        raise ImageNotFound("no camera image with this token in the site's data set") from None
    return contained(image.path, [context.dataset.root], token)


def lane_mask_file(context: CameraContext, token: str) -> Path | None:
    """The resolved lane-instance mask of a camera image (None when it has none), inside a mask root."""
    if context.dataset is None:
        raise ImageNotFound("the site has no data set")
    try:
        image = context.dataset.image(token)
    except KeyError:
        raise ImageNotFound("no camera image with this token in the site's data set") from None
    if image.instance_mask_path is None:
        return None
    return contained(image.instance_mask_path, context.dataset.mask_roots, token)


def scaled_jpeg(path: Path, width: int | None) -> bytes:
    """The image at `width` (aspect kept, OpenCV INTER_AREA), JPEG; a JPEG not made smaller is sent as is."""
    data = path.read_bytes()
    is_jpeg = data[:3] == b"\xff\xd8\xff"
    if is_jpeg and width is None:
        return data
    bgr = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
    if bgr is None:
        raise ValueError(f"{path}: not a readable image")
    if width is not None and width < bgr.shape[1]:
        height = max(1, round(bgr.shape[0] * width / bgr.shape[1]))
        bgr = cv2.resize(bgr, (width, height), interpolation=cv2.INTER_AREA)
    elif is_jpeg:
        return data
    ok, encoded = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
    if not ok:
        raise ValueError(f"{path}: cannot encode as JPEG")
    return encoded.tobytes()


def instance_colour(instance_id: int) -> tuple[int, int, int]:
    """A stable, well-separated RGB colour per lane instance id (golden-ratio hues)."""
    hue = (instance_id * 0.618033988749895) % 1.0
    red, green, blue = colorsys.hsv_to_rgb(hue, 0.85, 1.0)
    return round(red * 255), round(green * 255), round(blue * 255)


def lane_overlay_png(path: Path, width: int | None) -> bytes:
    """An RGBA PNG: each lane instance of a uint16 instance mask in its own colour at MASK_ALPHA, background
    transparent, scaled to `width` (nearest neighbour: ids are not blended)."""
    mask = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if mask is None or mask.ndim != 2:
        raise ValueError(f"{path}: not a single-channel instance mask")
    if width is not None and width != mask.shape[1]:
        height = max(1, round(mask.shape[0] * width / mask.shape[1]))
        mask = cv2.resize(mask, (width, height), interpolation=cv2.INTER_NEAREST)
    ids, inverse = np.unique(mask, return_inverse=True)
    lut = np.zeros((len(ids), 4), np.uint8)
    for index, instance_id in enumerate(ids.tolist()):
        if instance_id:
            red, green, blue = instance_colour(int(instance_id))
            lut[index] = (blue, green, red, MASK_ALPHA)  # OpenCV writes BGRA
    ok, encoded = cv2.imencode(".png", lut[inverse.reshape(mask.shape)])
    if not ok:
        raise ValueError(f"{path}: cannot encode the overlay")
    return encoded.tobytes()


def _etag(kind: str, path: Path, width: int | None) -> tuple[str, str]:
    """The cache key and ETag of a file at a width (from its resolved path, mtime and size)."""
    stat = os.stat(path)
    key = f"{kind}\0{path}\0{stat.st_mtime_ns}\0{stat.st_size}\0{width}"
    return key, '"' + hashlib.sha256(key.encode()).hexdigest()[:24] + '"'


@dataclass
class ImageCache:
    """Encoded images and overlays by (kind, file, mtime, size, width), least recently used evicted first."""

    max_bytes: int = CACHE_BYTES
    entries: "OrderedDict[str, Encoded]" = field(default_factory=OrderedDict)
    size: int = 0
    lock: threading.Lock = field(default_factory=threading.Lock)

    def etag(self, kind: str, path: Path, width: int | None) -> str:
        """The ETag the file would be served with (for a 304 without encoding anything)."""
        return _etag(kind, path, width)[1]

    def get(self, kind: str, path: Path, width: int | None) -> Encoded:
        """The encoded file (`image`: JPEG, `lane-mask`: RGBA PNG overlay), from the cache or made now."""
        key, etag = _etag(kind, path, width)
        with self.lock:
            found = self.entries.get(key)
            if found is not None:
                self.entries.move_to_end(key)
                return found
        if kind == "image":
            encoded = Encoded(scaled_jpeg(path, width), etag, "image/jpeg")
        else:
            encoded = Encoded(lane_overlay_png(path, width), etag, "image/png")
        with self.lock:
            if key not in self.entries:
                self.entries[key] = encoded
                self.size += len(encoded.data)
            while self.size > self.max_bytes and len(self.entries) > 1:
                _, dropped = self.entries.popitem(last=False)
                self.size -= len(dropped.data)
        return encoded
