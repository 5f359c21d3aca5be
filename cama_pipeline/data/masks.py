"""Where the image masks of a run come from: the data set's own, the workspace's (predicted by `cama segment`,
imported by `cama import-masks`) or a folder the user names.

A mask root is a folder laid out like a data set's masks: `<root>/semantic/<image path>.png` (uint8,
`cama_pipeline.semantics` ids) and `<root>/lane_instance/<image path>.png` (uint16, class * 1000 + index), with
`<image path>` from `cama_pipeline.data.schema.mask_relpath`. The loader takes an ordered tuple of roots and
gives each image, per mask kind, the file of the first root that holds it.

The choice (`MaskChoice`, `--masks` of every stage command and of `cama run`, key `masks` of a run configuration):

    auto       the data set's own masks where it has them, else the workspace's predicted, else its imported
               (every present source, in that order: masks from the data set win over predicted ones)
    dataset    only the data set's own masks (an error when it has none)
    predicted  only `<workspace>/masks/predicted` (an error naming the folder and `cama segment` when missing)
    imported   only `<workspace>/masks/imported` (an error naming the folder and `cama import-masks`)
    DIR        any other value: a folder laid out as a mask root

`masks_fingerprint` is what a stage puts in its fingerprint so that other masks rerun it: the choice and, per
root in use, the digest of its manifest (`masks/<source>/manifest.json`, written last by the command that made
the masks).
"""

import hashlib
import os
from pathlib import Path
from typing import Literal, TypeAlias, get_args

from cama_pipeline.data.errors import DatasetError
from cama_pipeline.data.schema import INSTANCE_DIR, SEMANTIC_DIR
from cama_pipeline.workspace import Workspace

MaskSource = Literal["auto", "dataset", "predicted", "imported"]
MASK_SOURCES: tuple[str, ...] = get_args(MaskSource)
"""The named choices; any other value is a folder."""
MaskChoice: TypeAlias = MaskSource | Path
"""Where a run's masks come from (see the module docstring)."""
MAKERS = {"predicted": "cama segment", "imported": "cama import-masks"}
"""The command that writes each workspace mask source."""
MANIFEST_NAME = "manifest.json"
"""A mask root's manifest (the workspace's: `Workspace.masks_manifest`), written last, so present means complete."""


def parse_mask_choice(text: str | Path) -> MaskChoice:
    """`auto`, `dataset`, `predicted`, `imported`, or any other value as a folder path; ValueError when empty."""
    if isinstance(text, Path):
        return text
    if not text.strip():
        raise ValueError("--masks: expected auto, dataset, predicted, imported or a folder, got ''")
    for source in MASK_SOURCES:
        if text == source:
            return source  # type: ignore[return-value]  # one of the literals
    return Path(text)


def mask_choice_label(choice: MaskChoice | str) -> str:
    """The choice as written on a command line or in a configuration (a folder as its path)."""
    return str(choice)


def has_masks(root: Path) -> bool:
    """Whether `root` holds a `semantic/` or `lane_instance/` folder."""
    return (Path(root) / SEMANTIC_DIR).is_dir() or (Path(root) / INSTANCE_DIR).is_dir()


def _workspace_root(workspace: Workspace, source: str) -> Path | None:
    """The workspace's mask root of `source` when the command that makes it finished (manifest present)."""
    return workspace.masks_dir(source) if workspace.masks_manifest(source).is_file() else None


def mask_roots(
    choice: MaskChoice | str, dataset_root: Path, workspace: Path | Workspace | None = None
) -> tuple[Path, ...]:
    """The mask roots of `choice`, in the order the loader tries them (see the module docstring). `auto` may
    give none (a data set without masks and a workspace without any); the named sources never do: a DatasetError
    (the data set has no masks) or FileNotFoundError (naming the folder and the command that makes it)."""
    dataset_root = Path(dataset_root).absolute()
    ws = Workspace.resolve(workspace, dataset_root)
    choice = parse_mask_choice(choice)
    if isinstance(choice, Path):
        folder = choice.absolute()
        if not has_masks(folder):
            raise FileNotFoundError(
                f"{folder}: mask folder has no {SEMANTIC_DIR}/ or {INSTANCE_DIR}/ inside "
                "(the data set's mask layout: <folder>/semantic/<image path>.png)"
            )
        return (folder,)
    if choice == "dataset":
        if not has_masks(dataset_root):
            raise DatasetError(
                f"the data set has no masks ({SEMANTIC_DIR}/, {INSTANCE_DIR}/); use --masks predicted "
                "(`cama segment`), --masks imported (`cama import-masks`) or --masks auto",
                path=dataset_root,
            )
        return (dataset_root,)
    if choice in MAKERS:
        root = _workspace_root(ws, choice)
        if root is None:
            raise FileNotFoundError(
                f"{ws.masks_dir(choice)}: no {choice} masks (no {MANIFEST_NAME}); run `{MAKERS[choice]}` first"
            )
        return (root,)
    found = [dataset_root] if has_masks(dataset_root) else []
    found += [root for source in MAKERS if (root := _workspace_root(ws, source)) is not None]
    return tuple(found)


def masks_fingerprint(
    choice: MaskChoice | str, roots: tuple[Path, ...], dataset_root: Path
) -> list[tuple[str, str | None]]:
    """What a stage's fingerprint holds of its masks: the choice, then per root its name (`dataset`, the workspace
    source's folder name, or the folder) and the digest of its manifest (None for the data set's own masks and a
    folder without one; such a folder gets a digest of its files' sizes and times instead)."""
    dataset_root = Path(dataset_root).absolute()
    parts: list[tuple[str, str | None]] = [("choice", mask_choice_label(choice))]
    for root in roots:
        if root == dataset_root:
            parts.append(("dataset", None))
            continue
        manifest = root / MANIFEST_NAME
        name = root.name if root.parent.name == "masks" else str(root)
        parts.append((name, _file_digest(manifest) if manifest.is_file() else _tree_digest(root)))
    return parts


def _file_digest(path: Path) -> str:
    """sha256 of a file's bytes, shortened."""
    return hashlib.sha256(path.read_bytes()).hexdigest()[:16]


def _tree_digest(root: Path) -> str:
    """A digest of the relative path, size and modification time of every mask file under `root` (a folder
    of masks made elsewhere without a manifest: any rewritten mask changes it)."""
    digest = hashlib.sha256()
    for kind in (SEMANTIC_DIR, INSTANCE_DIR):
        for folder, dirs, files in os.walk(root / kind):
            dirs.sort()
            for name in sorted(files):
                stat = os.stat(os.path.join(folder, name))
                relative = os.path.relpath(os.path.join(folder, name), root)
                digest.update(f"{relative}\0{stat.st_size}\0{stat.st_mtime_ns}\n".encode())
    return digest.hexdigest()[:16]


def prediction_needed(
    choice: MaskChoice | str, dataset_root: Path, workspace: Path | Workspace | None = None
) -> str | None:
    """Whether a whole run must run the segmenter (`cama segment`) for `choice`: None when it must (the segment
    stage itself then skips masks that are up to date), else why not. `predicted` always needs it; `auto` needs
    it unless the data set has masks or the workspace has imported masks and no predicted ones (predicted masks
    already there are kept up to date); `dataset`, `imported` and a folder never do."""
    choice = parse_mask_choice(choice)
    ws = Workspace.resolve(workspace, Path(dataset_root))
    if isinstance(choice, Path):
        return f"masks from {choice}"
    if choice in ("dataset", "imported"):
        return f"--masks {choice}"
    if choice == "predicted":
        return None
    if has_masks(Path(dataset_root)):
        return "the data set has its own masks"
    if _workspace_root(ws, "imported") is not None and _workspace_root(ws, "predicted") is None:
        return f"imported masks in {ws.masks_dir('imported')}"
    return None
