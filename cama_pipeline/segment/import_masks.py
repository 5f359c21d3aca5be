"""`cama import-masks`: semantic masks made by another network (Mask2Former or OneFormer trained on Cityscapes
or Mapillary Vistas, ...) brought into the workspace as the project's masks, `<workspace>/masks/imported/`.

Input: a folder of single-channel 8- or 16-bit PNGs holding the network's label ids, one per camera image, named
like the image in one of two layouts (the first found wins):

    DIR/<image path without extension>.png   e.g. DIR/samples/CAM_FRONT/n015-..._CAM_FRONT__1532402927612460.png
                                              (the data set's mask layout without the `semantic/` prefix)
    DIR/<image file stem>.png                 e.g. DIR/n015-..._CAM_FRONT__1532402927612460.png (flat; nuScenes
                                              image names are unique: they hold the log, camera and time)

Each mask is checked (single channel, the image's size) and mapped to the project's ids through a class map
(`cama_pipeline.segment.class_maps`); its lane instances (class * 1000 + index) come from those semantics
(`cama_pipeline.segment.instances.lane_instances`). Every image the pipeline needs must have a mask: the images
`cama segment` segments (`cama_pipeline.segment.stage.needed_images`: every key-frame (sample) camera image and,
once `cama keyframes` has run, every keyframe image); other images with a mask are imported too. Any error (a
mask of the wrong size or form, an unknown label id, a missing mask) names the file and leaves the workspace as it
was: the masks are written into a staging folder beside `masks/imported/`, with the manifest last
(`cama_pipeline.segment.io`), and renamed into place only when all are done. A rerun with the same masks, class
map and needed images does nothing.
"""

import logging
import multiprocessing
import os
import shutil
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated

import cv2
import numpy as np
import typer

from cama_pipeline.cli_options import DatasetArg, OverwriteOpt, WorkspaceOpt
from cama_pipeline.code_version import code_version
from cama_pipeline.console import INPUT_ERRORS, bad_input, console
from cama_pipeline.data import CameraImage, Dataset, DatasetError, load_dataset
from cama_pipeline.data.schema import INSTANCE_DIR, SEMANTIC_DIR, mask_relpath
from cama_pipeline.fingerprints import fingerprint
from cama_pipeline.io import atomic_write_image
from cama_pipeline.progress import StageProgress
from cama_pipeline.results import ItemResult, StageResult
from cama_pipeline.segment.class_maps import BUILTIN_CLASS_MAPS, ClassMap, load_class_map
from cama_pipeline.segment.instances import lane_instances
from cama_pipeline.segment.io import MaskManifest, read_mask_manifest, write_mask_manifest
from cama_pipeline.workspace import Workspace

logger = logging.getLogger(__name__)

SOURCE = "imported"
MASK_SUFFIX = ".png"


@dataclass(frozen=True)
class MaskFile:
    """One camera image and the mask found for it."""

    image: CameraImage
    filename: str
    """The image's path relative to the data set root (sample_data `filename`)."""
    mask: Path


def mask_candidates(folder: Path, filename: str) -> tuple[Path, Path]:
    """Where the mask of the image `filename` may be in `folder`: the nested layout, then the flat one."""
    stem = filename.rsplit(".", 1)[0]
    return folder / f"{stem}{MASK_SUFFIX}", folder / f"{Path(stem).name}{MASK_SUFFIX}"


def find_masks(dataset: Dataset, folder: Path, needed: list[str]) -> list[MaskFile]:
    """The mask of every image of the data set that has one in `folder`; FileNotFoundError naming the first
    needed images without one (and where their mask was looked for)."""
    found: list[MaskFile] = []
    for image in dataset.camera_images():
        filename = image.path.relative_to(dataset.root).as_posix()
        mask = next((path for path in mask_candidates(folder, filename) if path.is_file()), None)
        if mask is not None:
            found.append(MaskFile(image, filename, mask))
    have = {entry.filename for entry in found}
    missing = [name for name in needed if name not in have]
    if missing:
        nested, flat = mask_candidates(folder, missing[0])
        raise FileNotFoundError(
            f"{folder}: no mask for {len(missing)} of the {len(needed)} images the pipeline needs, e.g. "
            f"{dataset.root / missing[0]} (looked for {nested} and {flat}); nothing imported"
        )
    if not found:
        raise FileNotFoundError(
            f"{folder}: no mask named like an image of the data set (<image path>.png or <image name>.png)"
        )
    return found


def read_labels(path: Path, image: CameraImage) -> np.ndarray:
    """A mask's label ids: a single-channel 8- or 16-bit PNG of the image's size; DatasetError naming it."""
    labels = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if labels is None:
        raise DatasetError("mask cannot be decoded as an image", path=path, record=image.token)
    if labels.ndim != 2 or labels.dtype not in (np.uint8, np.uint16):
        channels = 1 if labels.ndim == 2 else labels.shape[2]
        raise DatasetError(
            f"mask must be a single-channel 8- or 16-bit PNG of label ids, got {channels} channel(s) of "
            f"{labels.dtype}",
            path=path,
            record=image.token,
        )
    width, height = image.calibration.width, image.calibration.height
    if labels.shape != (height, width):
        raise DatasetError(
            f"mask is {labels.shape[1]}x{labels.shape[0]} px, its image {image.path.name} is {width}x{height} px",
            path=path,
            record=image.token,
        )
    return np.asarray(labels)


def write_masks(entry: MaskFile, class_map: ClassMap, table: np.ndarray, root: Path) -> None:
    """Map one mask and write its semantic and lane-instance masks under the mask root `root`."""
    semantic = class_map.apply(read_labels(entry.mask, entry.image), entry.mask, table)
    atomic_write_image(root / mask_relpath(SEMANTIC_DIR, entry.filename), semantic)
    atomic_write_image(root / mask_relpath(INSTANCE_DIR, entry.filename), lane_instances(semantic))


_worker_state: tuple[ClassMap, np.ndarray, Path] | None = None


def _start_worker(class_map: ClassMap, root: Path) -> None:
    """Worker-process set-up: the class map, its lookup table and the staging root."""
    global _worker_state
    _worker_state = (class_map, class_map.table(), root)


def _write_in_worker(entry: MaskFile) -> None:
    if _worker_state is None:
        raise RuntimeError("import worker used before _start_worker")
    write_masks(entry, *_worker_state)


def write_all(
    found: list[MaskFile], class_map: ClassMap, root: Path, workers: int, show_progress: bool
) -> None:
    """`write_masks` of every entry, in `workers` processes when there are enough masks (lane instances take
    about 0.3 s of CPU for a 1600x900 mask), with a progress bar; the first bad mask stops it."""
    with StageProgress("import-masks", logger=logger, enabled=show_progress) as progress:
        task = progress.add_task("masks", total=len(found))
        if workers < 2 or len(found) < 2 * workers:
            table = class_map.table()
            for entry in found:
                write_masks(entry, class_map, table, root)
                progress.advance(task)
            return
        context = multiprocessing.get_context("spawn")  # forking a process that may hold threads is unsafe
        setup = (class_map, root)
        with ProcessPoolExecutor(
            workers, mp_context=context, initializer=_start_worker, initargs=setup
        ) as pool:
            for _ in pool.map(_write_in_worker, found, chunksize=8):
                progress.advance(task)


def _digest(class_map: ClassMap, folder: Path, found: list[MaskFile], needed: list[str]) -> str:
    """What the imported masks are made of: the code, the class map, every mask file and the needed images."""
    stats = []
    for entry in found:
        stat = entry.mask.stat()
        stats.append((entry.image.token, str(entry.mask.relative_to(folder)), stat.st_size, stat.st_mtime_ns))
    return fingerprint(
        code_version("cama_pipeline.segment.import_masks"),
        class_map.digest(),
        str(folder.absolute()),
        stats,
        sorted(needed),
    )


def _swap_in(staging: Path, target: Path) -> None:
    """Put the complete `staging` folder at `target`, the previous masks removed after."""
    old = target.with_name(f".{target.name}.previous")
    shutil.rmtree(old, ignore_errors=True)
    if target.exists():
        os.replace(target, old)
    os.replace(staging, target)
    shutil.rmtree(old, ignore_errors=True)


def import_masks(
    dataset_root: Path,
    folder: Path,
    class_map: ClassMap | str | Path,
    workspace: Path | Workspace | None = None,
    *,
    workers: int = 1,
    overwrite: bool = False,
    show_progress: bool = True,
) -> StageResult:
    """Import the masks in `folder` into `<workspace>/masks/imported/` (see the module docstring); its one item is
    that folder with its manifest. Bad input (DatasetError, ClassMapError, FileNotFoundError) names the file and
    leaves the workspace unchanged. `workers`: processes mapping the masks."""
    if workers < 1:
        raise ValueError(f"workers must be >= 1, got {workers}")
    started = time.perf_counter()
    dataset_root, folder = Path(dataset_root), Path(folder)
    ws = Workspace.resolve(workspace, dataset_root)
    if not folder.is_dir():
        raise FileNotFoundError(f"{folder}: mask folder not found")
    class_map = class_map if isinstance(class_map, ClassMap) else load_class_map(class_map)
    dataset = load_dataset(dataset_root, mask_roots=())
    from cama_pipeline.segment.stage import needed_images  # the segmenter's list (imports torch: only here)

    needed = needed_images(dataset, ws)
    found = find_masks(dataset, folder, needed)
    digest = _digest(class_map, folder, found, needed)
    target, manifest_path = ws.masks_dir(SOURCE), ws.masks_manifest(SOURCE)
    if not overwrite and manifest_path.is_file():
        previous = read_mask_manifest(manifest_path)
        if previous.fingerprint == digest:
            logger.info("imported masks in %s up to date", target)
            item = ItemResult(SOURCE, target, previous.to_json(), skipped=True)
            return StageResult("import-masks", ws, (item,), time.perf_counter() - started)
    staging = target.with_name(f".{target.name}.staging")
    shutil.rmtree(staging, ignore_errors=True)
    try:
        write_all(found, class_map, staging, workers, show_progress)
        manifest = _manifest(class_map, folder, found, needed, digest, time.perf_counter() - started)
        write_mask_manifest(staging / manifest_path.name, manifest)
        _swap_in(staging, target)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    item = ItemResult(SOURCE, target, manifest.to_json(), skipped=False)
    return StageResult("import-masks", ws, (item,), time.perf_counter() - started)


def _manifest(
    class_map: ClassMap, folder: Path, found: list[MaskFile], needed: list[str], digest: str, seconds: float
) -> MaskManifest:
    """What made the imported masks (the class map and the folder) and for which images
    (`cama_pipeline.segment.io` owns the format)."""
    return MaskManifest(
        source=SOURCE,
        made_by={
            "command": "cama import-masks",
            "folder": str(folder.absolute()),
            "class_map": {"name": class_map.name, "source": class_map.source, "digest": class_map.digest()},
        },
        images=tuple(entry.filename for entry in found),
        fingerprint=digest,
        seconds=round(seconds, 2),
        extra={"needed_images": len(needed)},
    )


def import_masks_command(
    dataset: DatasetArg,
    masks_dir: Annotated[
        Path,
        typer.Argument(
            metavar="DIR",
            help="Folder of single-channel label PNGs: DIR/<image path>.png (e.g. DIR/samples/CAM_FRONT/x.png) "
            "or DIR/<image name>.png.",
        ),
    ],
    class_map: Annotated[
        str,
        typer.Option(help=f"{', '.join(BUILTIN_CLASS_MAPS)} or a class map FILE.json (cama.class_map/1)."),
    ],
    workspace: WorkspaceOpt = None,
    workers: Annotated[
        int, typer.Option(min=1, help="Processes mapping masks and finding lane instances.")
    ] = 2,
    overwrite: OverwriteOpt = False,
) -> None:
    """Import another network's masks (Cityscapes or Mapillary Vistas labels, or any FILE.json class map) as the
    workspace's masks (`--masks imported`); nothing is imported unless every mask is good."""
    try:
        result = import_masks(dataset, masks_dir, class_map, workspace, workers=workers, overwrite=overwrite)
    except INPUT_ERRORS as err:
        raise bad_input(err) from err
    (item,) = result.items
    state = "up to date" if item.skipped else f"{result.seconds:.1f} s"
    console.print(
        f"[green]imported[/green] {len(item.report['images'])} masks through class map "
        f"{item.report['made_by']['class_map']['name']} ({state}) -> {item.path}"
    )
