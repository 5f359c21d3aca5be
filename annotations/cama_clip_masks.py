"""Lane instance masks of CAMA clip data: `lane_ins_camera_<cam>/<ms>.png`, 16-bit, in CAMA's ids.

CAMA's metric code (its `MetricEvaluation.load_instance` / `semantic_id_remap`, read in the public CAMA code via
the code search: the reprojection module with `MapManager` / `CameraManager` and the metric module with
`MetricEvaluation`) reads each pixel as `semantic_id * 1000 + instance_id`, 0 = background, and names the semantics
0-6 `lane_marking` and 7 `Road_teeth`; any other semantic is "Unknown" and never scored (its SRE scores only
`lane_marking`). It reads the PNG with `cv2.IMREAD_ANYDEPTH` and resizes it with nearest-neighbour remapping
through the camera's `K` and `image_width` / `image_height`, so the mask must have the image's size.

The one id table (ours, `cama_pipeline.semantics`, lane_instance masks `class * 1000 + index` -> CAMA's):

    ours                      CAMA semantic   written value
    LANE_MARKING (3)          1 (lane_marking)  1000 + index
    CURB (2)                  7 (Road_teeth)    7000 + index
    CROSSWALK (4), any other  none            0 (left out, counted in `CamaMasks.dropped_instances`)

Lane markings get CAMA semantic 1, not 0: with semantic 0 the instance with our index 0 would be written as 0,
which CAMA reads as background. Crosswalks are left out because CAMA's table has no id for them (8 and up read
as "Unknown" and are dropped by its metric); inventing one would be a guess at a table CAMA does not define.
"""

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from cama_pipeline.data import CameraImage
from cama_pipeline.data.schema import INSTANCE_DIR, mask_relpath
from cama_pipeline.semantics import INSTANCE_ID_BASE, Semantic

CAMA_SEMANTIC_FROM_OURS: dict[Semantic, int] = {Semantic.LANE_MARKING: 1, Semantic.CURB: 7}
"""Our lane_instance class -> CAMA's semantic id (the table of the module docstring); others are left out."""
CAMA_SEMANTIC_NAMES: dict[int, str] = {1: "lane_marking", 7: "Road_teeth"}
"""What CAMA's code calls the semantic ids we write."""
MASK_DIR_PREFIX = "lane_ins_"
"""A camera's mask folder is `lane_ins_<camera name>` beside the camera's image folder."""

LaneMaskLookup = Callable[[CameraImage], Path | None]
"""Where an image's lane instance mask is (uint16, our ids), or None when it has none."""


@dataclass(frozen=True)
class CamaMask:
    """One image's lane instance mask in CAMA's ids, and what of ours was left out."""

    ids: np.ndarray
    """(H, W) uint16 `cama_semantic * 1000 + index`, 0 = background."""
    dropped_instances: dict[int, int]
    """Per class of ours without a CAMA id (e.g. 4 crosswalk): how many instances were left out."""


def dataset_lane_masks(image: CameraImage) -> Path | None:
    """The data set's own lookup: the image's lane instance mask in the mask roots the data set was loaded with."""
    return image.instance_mask_path


def lane_masks_in(roots: Sequence[Path], dataset_root: Path) -> LaneMaskLookup:
    """A lookup over mask roots laid out like a data set's masks (`cama_pipeline.data.masks.mask_roots`): the
    first root holding `lane_instance/<image path>.png` wins, as the data set loader does."""
    resolved_roots = tuple(Path(r).absolute() for r in roots)
    base = Path(dataset_root).absolute()

    def lookup(image: CameraImage) -> Path | None:
        try:
            relative = image.path.absolute().relative_to(base)
        except ValueError:
            raise ValueError(f"{image.path}: image is not under the data set root {base}") from None
        name = mask_relpath(INSTANCE_DIR, relative.as_posix())
        return next((root / name for root in resolved_roots if (root / name).is_file()), None)

    return lookup


def resolve_lane_masks(
    lane_masks: LaneMaskLookup | Sequence[Path] | None, dataset_root: Path
) -> LaneMaskLookup:
    """The lookup for `write_clip_data`'s `lane_masks`: None = the data set's own lookup, a sequence = mask
    roots, a callable = itself."""
    if lane_masks is None:
        return dataset_lane_masks
    if callable(lane_masks):
        return lane_masks
    return lane_masks_in(tuple(lane_masks), dataset_root)


def read_our_lane_mask(path: Path, width: int, height: int) -> np.ndarray:
    """Our uint16 lane instance mask at `path`; ValueError naming the file when unreadable, not single-channel
    uint16, or not `width` x `height` (CAMA resizes it with the image's calibration)."""
    mask = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if mask is None:
        raise ValueError(f"{path}: lane instance mask missing or not decodable")
    if mask.ndim != 2 or mask.dtype != np.uint16:
        raise ValueError(
            f"{path}: lane instance mask must be single-channel uint16, got {mask.dtype} {mask.shape}"
        )
    if mask.shape != (height, width):
        raise ValueError(
            f"{path}: lane instance mask is {mask.shape[1]}x{mask.shape[0]} px, its image {width}x{height} px"
        )
    return mask


def cama_lane_mask(ours: np.ndarray) -> CamaMask:
    """Our `class * 1000 + index` ids converted to CAMA's (the module's table); the index is kept."""
    ours = np.asarray(ours)
    classes = ours // INSTANCE_ID_BASE
    index = ours % INSTANCE_ID_BASE
    out = np.zeros(ours.shape, dtype=np.uint16)
    for our_class, cama_semantic in CAMA_SEMANTIC_FROM_OURS.items():
        selected = classes == int(our_class)
        out[selected] = (cama_semantic * INSTANCE_ID_BASE + index[selected]).astype(np.uint16)
    dropped: dict[int, int] = {}
    for value in np.unique(ours[ours != 0]):
        left_out = int(value) // INSTANCE_ID_BASE
        if left_out not in CAMA_SEMANTIC_FROM_OURS:
            dropped[left_out] = dropped.get(left_out, 0) + 1
    return CamaMask(out, dropped)
