"""Iterating in chunks: work done a batch at a time (image pairs matched per BLAS call, records encoded per
`json.dumps` call) without building the whole sequence of batches first; and counting what passes, a batch at a
time (a progress bar over millions of records)."""

import itertools
from collections.abc import Callable, Iterable, Iterator
from typing import TypeVar

T = TypeVar("T")


def chunked(items: Iterable[T], size: int) -> Iterator[list[T]]:
    """Consecutive lists of `size` items in order, the last one shorter."""
    iterator = iter(items)
    while chunk := list(itertools.islice(iterator, size)):
        yield chunk


def counted(
    items: Iterable[T], on_count: Callable[[int], None] | None, *, every: int = 65_536
) -> Iterator[T]:
    """`items` as they are, calling `on_count(n)` after each `every` items and with the rest at the end (once the
    iteration is exhausted): a progress bar advanced per batch, not per item. None: no calls."""
    if on_count is None:
        yield from items
        return
    if every < 1:
        raise ValueError(f"every: must be >= 1, got {every}")
    pending = 0
    for item in items:
        yield item
        pending += 1
        if pending == every:
            on_count(pending)
            pending = 0
    if pending:
        on_count(pending)
