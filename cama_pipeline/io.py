"""Atomic file writes (every output is written to a temporary file beside it, then renamed) and checked reads
of the pipeline's JSON files (a schema tag, typed fields, errors naming the file and field)."""

import json
import os
import tempfile
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import cv2
import numpy as np


def atomic_write_bytes(path: Path, data: bytes) -> None:
    """Write `data` to `path` so that readers see either the old file or the whole new one."""
    atomic_write_chunks(path, (data,))


def atomic_write_chunks(path: Path, chunks: Iterable[bytes | str]) -> None:
    """Write the chunks (str as UTF-8) one after another to `path` atomically: a file too large to hold in
    memory as one string is written as it is produced."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp_name = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as handle:
            for chunk in chunks:
                handle.write(chunk.encode("utf-8") if isinstance(chunk, str) else chunk)
        os.replace(tmp_name, path)
    except BaseException:
        Path(tmp_name).unlink(missing_ok=True)
        raise


def atomic_write_json(path: Path, obj: Any, *, indent: int | None = None) -> None:
    """Write `obj` as JSON (UTF-8) atomically."""
    atomic_write_bytes(path, json.dumps(obj, indent=indent).encode("utf-8"))


def atomic_write_image(path: Path, image: np.ndarray, *, jpeg_quality: int = 92) -> None:
    """Encode `image` (BGR or single channel) by the file's extension and write it atomically."""
    path = Path(path)
    params = [cv2.IMWRITE_JPEG_QUALITY, jpeg_quality] if path.suffix.lower() in (".jpg", ".jpeg") else []
    ok, encoded = cv2.imencode(path.suffix, image, params)
    if not ok:
        raise ValueError(f"could not encode an image of shape {image.shape} as {path.suffix}: {path}")
    atomic_write_bytes(path, encoded.tobytes())


def atomic_write_npy(path: Path, array: np.ndarray) -> None:
    """Save a numpy array as .npy atomically."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp_name = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as handle:
            np.save(handle, array)
        os.replace(tmp_name, path)
    except BaseException:
        Path(tmp_name).unlink(missing_ok=True)
        raise


class WorkspaceError(ValueError):
    """A workspace file that is missing a stage's output or breaks its schema; names file and field."""


def read_json(path: Path, schema: str, stage_hint: str) -> dict[str, Any]:
    """A JSON object whose `schema` field is `schema`; FileNotFoundError says which command writes it,
    WorkspaceError names the file when it is not valid JSON or of another schema."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: not found; run `{stage_hint}` first")
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as err:
        raise WorkspaceError(f"{path}: not valid JSON ({err})") from None
    if not isinstance(data, dict) or data.get("schema") != schema:
        found = data.get("schema") if isinstance(data, dict) else type(data).__name__
        raise WorkspaceError(f"{path}: field 'schema' must be {schema!r}, got {found!r}")
    return data


def field(
    data: Mapping[str, Any], name: str, kind: type | tuple[type, ...], path: Path, where: str = ""
) -> Any:
    """data[name] checked to be of `kind` (a bool is not an int), else a WorkspaceError naming the file and the
    field (`where` prefixes it, e.g. "poses[3].")."""
    if name not in data or not isinstance(data[name], kind) or isinstance(data[name], bool) and kind is int:
        raise WorkspaceError(f"{path}: field {where}{name!r} missing or not {kind}")
    return data[name]
