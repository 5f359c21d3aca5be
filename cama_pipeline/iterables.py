"""Iterating in chunks: work done a batch at a time (image pairs matched per BLAS call, records encoded per
`json.dumps` call) without building the whole sequence of batches first."""

import itertools
from collections.abc import Iterable, Iterator
from typing import TypeVar

T = TypeVar("T")


def chunked(items: Iterable[T], size: int) -> Iterator[list[T]]:
    """Consecutive lists of `size` items in order, the last one shorter."""
    iterator = iter(items)
    while chunk := list(itertools.islice(iterator, size)):
        yield chunk
