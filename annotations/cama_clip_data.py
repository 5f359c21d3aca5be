"""Clip data for CAMA's published reprojection and metric code (issue 24.4), in one release scene folder:

    <scene_dir>/attribute.json                  sync lists and calibration (`annotations.cama_clip_sync`)
    <scene_dir>/camera_<cam>/<ms>.jpg           the data set's JPEG bytes, hard-linked (same file system) or
                                                copied, never re-encoded; every image the sync lists name
    <scene_dir>/lane_ins_camera_<cam>/<ms>.png  16-bit lane instance mask in CAMA's ids (`annotations.cama_clip_masks`)
    <scene_dir>/clip_data.json                  our sidecar (CAMA's tools ignore it): the sync tolerance, the
                                                camera_front frames dropped from the sync and why, the mask id
                                                table, the images without a lane instance mask, the instances
                                                left out (crosswalks)

`maps/` and `odometry/` of the same folder are `annotations.cama_release`'s. `<cam>` is CAMA's camera name
(`annotations.cama_odometry.CAMERA_NAME_FROM_CHANNEL`: CAM_BACK* is camera_rear*).

An image without a lane instance mask gets no mask file; the result and the sidecar list them. CAMA's metric
reads every camera's mask at every sync index (from index 1) and fails on a missing file, so a scene with
missing masks runs there only after they are made (`cama segment` / `cama import-masks`, then export again).

Files are written atomically one by one, masks first, then images, then `attribute.json` and the sidecar, so an
error (a bad mask, a missing image) leaves no `attribute.json`; the export stages the whole folder.
"""

import logging
import os
import uuid
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from annotations.cama_clip_masks import (
    CAMA_SEMANTIC_FROM_OURS,
    CAMA_SEMANTIC_NAMES,
    MASK_DIR_PREFIX,
    LaneMaskLookup,
    cama_lane_mask,
    read_our_lane_mask,
    resolve_lane_masks,
)
from annotations.cama_clip_sync import (
    DEFAULT_MAX_SYNC_DIFF_MS,
    REFERENCE_CAMERA,
    ClipSync,
    DroppedFrame,
    attribute_json,
    sync_scene,
)
from annotations.cama_odometry import timestamp_ms
from cama_pipeline.data import CameraImage, Dataset, Scene
from cama_pipeline.io import atomic_write_bytes, atomic_write_image, atomic_write_json
from cama_pipeline.progress import StageProgress

logger = logging.getLogger(__name__)

ATTRIBUTE_JSON = "attribute.json"
SIDECAR_JSON = "clip_data.json"
SIDECAR_FORMAT = "cama-studio-clip-data"
JPEG_SUFFIXES = (".jpg", ".jpeg")


@dataclass(frozen=True)
class MissingMask:
    """A synchronised image that has no lane instance mask (so no `lane_ins_*` file)."""

    camera: str
    """CAMA camera name."""
    timestamp_ms: int
    """The image's millisecond time (its file name)."""
    image: str
    """The image's path in the data set (relative to its root where it lies under it)."""


@dataclass(frozen=True)
class ClipDataResult:
    """What `write_clip_data` wrote for one scene."""

    scene: str
    frames: int
    """Length of every sync list (camera_front images kept)."""
    cameras: tuple[str, ...]
    """CAMA camera names written, camera_front first."""
    dropped_frames: tuple[DroppedFrame, ...]
    """camera_front images left out of the sync lists (a camera without an image within the tolerance)."""
    images_written: int
    """Distinct images placed under `camera_<cam>/` (linked or copied)."""
    images_linked: int
    """Of those, how many are hard links to the data set's file."""
    masks_written: int
    """Lane instance masks written under `lane_ins_camera_<cam>/`."""
    missing_masks: tuple[MissingMask, ...]
    """Images without a lane instance mask (no mask file written)."""
    dropped_mask_instances: dict[int, int] = field(default_factory=dict)
    """Per class of ours without a CAMA id (4 = crosswalk): instances left out of the masks, summed."""

    @property
    def masks_missing(self) -> int:
        """How many synchronised images have no mask file."""
        return len(self.missing_masks)


def find_scene(dataset: Dataset, scene: str) -> Scene:
    """The scene named `scene`; ValueError naming it and the known scene names."""
    for candidate in dataset.scenes:
        if candidate.name == scene:
            return candidate
    known = [s.name for s in dataset.scenes]
    raise ValueError(f"scene {scene!r} is not in the data set {dataset.root}; known scenes: {known}")


def write_clip_data(
    scene_dir: Path,
    dataset: Dataset,
    scene: str,
    *,
    lane_masks: LaneMaskLookup | Sequence[Path] | None = None,
    max_sync_diff_ms: float = DEFAULT_MAX_SYNC_DIFF_MS,
    link_images: bool = True,
    show_progress: bool = False,
) -> ClipDataResult:
    """Write one scene's clip data into `scene_dir` (the module docstring's layout).

    `lane_masks`: where each image's lane instance mask (our ids) is: None = the data set's own lookup (the
    mask roots it was loaded with, `load_dataset(root, mask_roots=...)`), a sequence = mask roots
    (`cama_pipeline.data.masks.mask_roots`), or a callable image -> Path | None. `max_sync_diff_ms`: the sync
    tolerance (CAMA's 40 ms). `link_images`: hard-link the images where the file system allows (else copy).
    ValueError for an unknown scene (naming the known ones), a scene without camera_front images or without one
    synchronised frame, a camera whose images do not share one calibration, a non-JPEG image or a bad mask.
    """
    found = find_scene(dataset, scene)
    lookup = resolve_lane_masks(lane_masks, dataset.root)
    sync = sync_scene(found, max_diff_ms=max_sync_diff_ms)
    attributes = attribute_json(found, sync)  # validates calibration before anything is written
    images = sync.images()
    for camera_images in images.values():
        for image in camera_images:
            _check_image(image)
    scene_dir = Path(scene_dir)
    total = sum(len(v) for v in images.values())
    linked = masks = 0
    missing: list[MissingMask] = []
    dropped: dict[int, int] = {}
    with StageProgress("cama export", logger=logger, enabled=show_progress) as progress:
        task = progress.add_task(f"clip data {scene}", total=total)
        for camera, camera_images in images.items():
            for image in camera_images:
                ms = timestamp_ms(image.timestamp_us)
                mask_path = lookup(image)
                if mask_path is None:
                    missing.append(MissingMask(camera, ms, _dataset_relative(image, dataset)))
                else:
                    for our_class, count in _write_mask(image, mask_path, scene_dir, camera, ms).items():
                        dropped[our_class] = dropped.get(our_class, 0) + count
                    masks += 1
                linked += _place_image(image.path, scene_dir / camera / f"{ms}.jpg", link=link_images)
                progress.advance(task)
    result = ClipDataResult(
        scene=scene,
        frames=len(sync.rows),
        cameras=sync.cameras,
        dropped_frames=sync.dropped,
        images_written=total,
        images_linked=linked,
        masks_written=masks,
        missing_masks=tuple(missing),
        dropped_mask_instances=dict(sorted(dropped.items())),
    )
    atomic_write_json(scene_dir / ATTRIBUTE_JSON, attributes, indent=1)
    atomic_write_json(scene_dir / SIDECAR_JSON, sidecar(result, sync, max_sync_diff_ms), indent=1)
    if missing:
        logger.warning("scene %s: %d of %d images have no lane instance mask", scene, len(missing), total)
    return result


def sidecar(result: ClipDataResult, sync: ClipSync, max_sync_diff_ms: float) -> dict[str, object]:
    """Our `clip_data.json`: what CAMA's files do not say about how they were made."""
    return {
        "format": SIDECAR_FORMAT,
        "format_version": 1,
        "scene": result.scene,
        "reference_camera": REFERENCE_CAMERA,
        "max_sync_diff_ms": max_sync_diff_ms,
        "frames": result.frames,
        "dropped_frames": [
            {"timestamp_ms": d.timestamp_ms, "cameras_without_image": list(d.cameras_without_image)}
            for d in sync.dropped
        ],
        "mask_ids": {
            "encoding": "semantic * 1000 + instance index, 0 = background",
            "from_ours": {
                str(int(ours)): {
                    "cama_semantic": cama,
                    "cama_name": CAMA_SEMANTIC_NAMES[cama],
                    "ours": ours.name,
                }
                for ours, cama in CAMA_SEMANTIC_FROM_OURS.items()
            },
            "left_out_instances": {str(k): v for k, v in result.dropped_mask_instances.items()},
        },
        "images": {"written": result.images_written, "hard_linked": result.images_linked},
        "masks_written": result.masks_written,
        "missing_masks": [
            {"camera": m.camera, "timestamp_ms": m.timestamp_ms, "image": m.image}
            for m in result.missing_masks
        ],
    }


def _check_image(image: CameraImage) -> None:
    """FileNotFoundError / ValueError naming the image when it is missing or not a JPEG (CAMA reads `.jpg`; we
    never re-encode)."""
    if image.path.suffix.lower() not in JPEG_SUFFIXES:
        raise ValueError(f"{image.path}: CAMA clip data holds JPEG images (.jpg); this image is not one")
    if not image.path.is_file():
        raise FileNotFoundError(f"{image.path}: image not found (sample_data {image.token})")


def _dataset_relative(image: CameraImage, dataset: Dataset) -> str:
    """The image's path relative to the data set root, or absolute where it is not under it."""
    try:
        return image.path.relative_to(dataset.root).as_posix()
    except ValueError:
        return str(image.path)


def _write_mask(image: CameraImage, mask_path: Path, scene_dir: Path, camera: str, ms: int) -> dict[int, int]:
    """Convert and write one mask; the instances left out per class of ours."""
    calibration = image.calibration
    ours = read_our_lane_mask(mask_path, calibration.width, calibration.height)
    converted = cama_lane_mask(ours)
    atomic_write_image(scene_dir / f"{MASK_DIR_PREFIX}{camera}" / f"{ms}.png", converted.ids)
    return converted.dropped_instances


def _place_image(source: Path, target: Path, *, link: bool) -> int:
    """Put the data set's image bytes at `target` atomically: a hard link when `link` and the file system
    allows it (returns 1), else a byte copy (returns 0)."""
    target.parent.mkdir(parents=True, exist_ok=True)
    if link:
        temporary = target.with_name(f".{target.name}.{uuid.uuid4().hex}.tmp")
        try:
            os.link(source, temporary)
            os.replace(temporary, target)
            return 1
        except OSError:
            temporary.unlink(missing_ok=True)
    atomic_write_bytes(target, source.read_bytes())
    return 0
