"""Atomic file writes: every output is written to a temporary file beside it, then renamed."""

import json
import os
import tempfile
from pathlib import Path
from typing import Any

import cv2
import numpy as np


def atomic_write_bytes(path: Path, data: bytes) -> None:
    """Write `data` to `path` so that readers see either the old file or the whole new one."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp_name = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as handle:
            handle.write(data)
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
