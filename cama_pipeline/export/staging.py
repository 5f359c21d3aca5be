"""Write a whole export (a folder or one file) beside its final name, then rename it into place.

A reader of the final name sees the previous export or the complete new one, never a half-written one: the
writer fills `.<name>.partial-<random>` in the same folder (same file system, so the rename is atomic), and a
failure removes it. An existing export is replaced only when asked (`overwrite`); it is moved aside first and
removed after the new one is in place.
"""

import shutil
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path


def _remove(path: Path) -> None:
    """Remove a file or folder if present."""
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    else:
        path.unlink(missing_ok=True)


@contextmanager
def staged_output(out: Path, *, overwrite: bool = False) -> Iterator[Path]:
    """Yield a fresh staging path beside `out` (not created: the writer makes a folder or a file there); on
    success rename it to `out`. FileExistsError naming `out` when it exists and `overwrite` is False."""
    out = Path(out).absolute()
    if out.exists() and not overwrite:
        raise FileExistsError(f"{out}: already exists; pass --overwrite to replace it")
    out.parent.mkdir(parents=True, exist_ok=True)
    token = uuid.uuid4().hex[:12]
    staging = out.parent / f".{out.name}.partial-{token}"
    try:
        yield staging
        if not staging.exists():
            raise RuntimeError(f"{staging}: the export wrote nothing")
        previous = out.parent / f".{out.name}.old-{token}"
        if out.exists():
            out.rename(previous)
        try:
            staging.rename(out)
        except OSError:
            if previous.exists():
                previous.rename(out)
            raise
        _remove(previous)
    except BaseException:
        _remove(staging)
        raise
