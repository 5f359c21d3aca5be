"""`cama_pipeline.iterables`: batches in order with a shorter last one, and counts reported a batch at a time
with nothing lost or counted twice."""

import pytest

from cama_pipeline.iterables import chunked, counted


def test_chunked_keeps_order_and_ends_with_the_rest():
    assert list(chunked(range(7), 3)) == [[0, 1, 2], [3, 4, 5], [6]]
    assert list(chunked(range(6), 3)) == [[0, 1, 2], [3, 4, 5]]
    assert list(chunked([], 3)) == []
    assert list(chunked(iter("ab"), 5)) == [["a", "b"]]


@pytest.mark.parametrize(
    ("n", "every", "calls"), [(0, 3, []), (2, 3, [2]), (6, 3, [3, 3]), (7, 3, [3, 3, 1])]
)
def test_counted_yields_everything_and_counts_each_item_once(n, every, calls):
    seen: list[int] = []
    assert list(counted(range(n), seen.append, every=every)) == list(range(n))
    assert seen == calls and sum(seen) == n


def test_counted_reports_as_the_items_are_consumed_not_before():
    seen: list[int] = []
    items = counted(range(5), seen.append, every=2)
    assert [next(items), next(items)] == [0, 1] and seen == []  # reported once the consumer asks for more
    assert next(items) == 2 and seen == [2]
    assert list(items) == [3, 4] and seen == [2, 2, 1]


def test_counted_without_a_callback_and_a_bad_batch():
    assert list(counted("abc", None)) == ["a", "b", "c"]
    with pytest.raises(ValueError, match="every: must be >= 1"):
        list(counted("abc", print, every=0))
