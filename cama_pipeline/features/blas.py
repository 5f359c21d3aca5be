"""Single-threaded BLAS while our own worker threads run many small matrix products.

numpy's OpenBLAS splits each product over every core; for 900 x 900 descriptor products run from two worker
threads on two cores that oversubscription cost 16.5 ms of CPU per pair instead of 5.1 ms (default site,
1,000 pairs). OpenBLAS offers no per-call setting, so its thread count is lowered for the duration and restored.
Where numpy carries no OpenBLAS (another BLAS build), nothing is changed.
"""

import ctypes
import logging
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np

logger = logging.getLogger(__name__)
_SETTERS = ("scipy_openblas_set_num_threads64_", "scipy_openblas_set_num_threads", "openblas_set_num_threads")
_GETTERS = ("scipy_openblas_get_num_threads64_", "scipy_openblas_get_num_threads", "openblas_get_num_threads")


def _openblas() -> tuple[Callable[[int], None], Callable[[], int]] | None:
    """numpy's bundled OpenBLAS thread setter and getter, or None when it has none."""
    libs = Path(np.__file__).parent.parent / "numpy.libs"
    for path in sorted(libs.glob("*openblas*")):
        library = ctypes.CDLL(str(path))
        setter = next((getattr(library, n) for n in _SETTERS if hasattr(library, n)), None)
        getter = next((getattr(library, n) for n in _GETTERS if hasattr(library, n)), None)
        if setter is not None and getter is not None:
            return setter, getter
    return None


@contextmanager
def single_threaded_blas() -> Iterator[None]:
    """numpy's BLAS on one thread inside the block (callers parallelise over their own work items)."""
    found = _openblas()
    if found is None:
        logger.debug("no bundled OpenBLAS found: BLAS threads left as they are")
        yield
        return
    setter, getter = found
    before = int(getter())
    setter(1)
    try:
        yield
    finally:
        setter(before)
