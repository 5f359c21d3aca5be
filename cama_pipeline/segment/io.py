"""The workspace's mask roots, `masks/<source>/` (`Workspace.masks_dir`): the only module that reads or writes
their manifest and the segment stage's progress journal.

A mask root is laid out as a data set's masks (`semantic/<image path>.png` uint8, `lane_instance/<image path>.png`
uint16, `<image path>` from `cama_pipeline.data.schema.mask_relpath`), plus:

    manifest.json   written last by the command that made the masks, so present means complete
                    (`cama_pipeline.data.masks` reads only its presence and its digest);
        schema "cama.masks/1":
        {"schema", "source": "predicted" | "imported",
         "made_by": {"command": ..., and what identifies the maker: the checkpoint's label, path and
                     weights digest for `cama segment`, the class map and folder for `cama import-masks`},
         "images": [sample_data filename of every image with masks here, sorted],
         "fingerprint": digest of the maker and the images (a rerun that matches it does nothing),
         "seconds": how long making them took, ... any further fields the maker records}
    .progress.json  the segment stage's journal while it runs (removed when the manifest is written):
        schema "cama.masks-progress/1": {"schema", "made_with": digest of the checkpoint and stage code,
                                         "images": [filenames whose masks are written]}
        an interrupted run leaves it, and the next run with the same checkpoint skips those images.
"""

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from cama_pipeline.io import WorkspaceError, atomic_write_json, read_json
from cama_pipeline.io import field as checked

MASKS_SCHEMA = "cama.masks/1"
PROGRESS_SCHEMA = "cama.masks-progress/1"
PROGRESS_NAME = ".progress.json"
_KNOWN = ("schema", "source", "made_by", "images", "fingerprint", "seconds")


@dataclass(frozen=True)
class MaskManifest:
    """Contents of `masks/<source>/manifest.json`."""

    source: str
    """`predicted` or `imported` (the workspace's mask sources)."""
    made_by: dict[str, Any]
    """The command and what identifies its model or class map."""
    images: tuple[str, ...]
    """sample_data filenames of the images with masks in this root, sorted."""
    fingerprint: str
    seconds: float = 0.0
    extra: dict[str, Any] = field(default_factory=dict)
    """Further fields the maker records (e.g. the class map, counts)."""

    def to_json(self) -> dict[str, Any]:
        return {
            "schema": MASKS_SCHEMA,
            "source": self.source,
            "made_by": dict(self.made_by),
            "images": sorted(self.images),
            "fingerprint": self.fingerprint,
            "seconds": self.seconds,
            **self.extra,
        }


def write_mask_manifest(path: Path, manifest: MaskManifest) -> None:
    """Write a mask root's manifest atomically (the last file a command writes into the root)."""
    atomic_write_json(path, manifest.to_json(), indent=1)


def read_mask_manifest(path: Path) -> MaskManifest:
    """Read and check a mask root's manifest; WorkspaceError naming the file and field when it breaks the schema."""
    data = read_json(path, MASKS_SCHEMA, "cama segment` or `cama import-masks")
    images = checked(data, "images", list, path)
    if not all(isinstance(name, str) for name in images):
        raise WorkspaceError(f"{path}: field 'images' must list image filenames")
    seconds = data.get("seconds", 0.0)
    if isinstance(seconds, bool) or not isinstance(seconds, int | float):
        raise WorkspaceError(f"{path}: field 'seconds' must be a number")
    return MaskManifest(
        source=checked(data, "source", str, path),
        made_by=checked(data, "made_by", dict, path),
        images=tuple(images),
        fingerprint=checked(data, "fingerprint", str, path),
        seconds=float(seconds),
        extra={k: v for k, v in data.items() if k not in _KNOWN},
    )


def progress_path(mask_root: Path) -> Path:
    """`<mask root>/.progress.json`: the segment stage's journal."""
    return Path(mask_root) / PROGRESS_NAME


def write_progress(mask_root: Path, made_with: str, images: list[str]) -> None:
    """Record, atomically, which images' masks a running segment stage has written with `made_with`."""
    atomic_write_json(
        progress_path(mask_root),
        {"schema": PROGRESS_SCHEMA, "made_with": made_with, "images": sorted(images)},
    )


def read_progress(mask_root: Path, made_with: str) -> set[str]:
    """The images an interrupted run wrote with `made_with`; empty when there is no journal, it is unreadable
    (it is only a shortcut: those images are then segmented again) or it was made with something else."""
    path = progress_path(mask_root)
    if not path.is_file():
        return set()
    try:
        data = read_json(path, PROGRESS_SCHEMA, "cama segment")
    except (WorkspaceError, OSError):
        return set()
    images = data.get("images")
    if data.get("made_with") != made_with or not isinstance(images, list):
        return set()
    return {name for name in images if isinstance(name, str)}
