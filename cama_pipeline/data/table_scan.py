"""Reading only some records of a large nuScenes table, without parsing the rest.

nuScenes v1.0-trainval's `sample_data.json` and `ego_pose.json` hold 2.6 million records each (1.3 GB and 0.4 GB
of JSON). Parsed whole they take half a minute and over 5 GB of memory (`bench/loader.py`), however few of their
records a stage needs. Their records are flat objects (lists as values, never nested objects), so a record can be
found by one of its string fields: the file is memory-mapped, a regular expression finds every `"key": "value"`,
and only the records whose value is wanted are cut out (the nearest `{` before the key to the next `}` after it)
and parsed. Anything that does not fit that shape (the file not one JSON list; a record that does not parse on
its own or whose key is not the one matched: a nested object or a brace inside a string; an escape in a key's
value) falls back to parsing the whole file, which then reports a syntax error by line and column as
`read_records` does.
"""

import json
import mmap
import os
import re
from collections.abc import Iterable
from collections.abc import Set as AbstractSet
from pathlib import Path

from cama_pipeline.data.errors import DatasetError
from cama_pipeline.data.tables import Record, check_fields, read_records


def select_records(path: Path, fields: Iterable[str], key: str, wanted: AbstractSet[str]) -> list[Record]:
    """The records of the JSON list table at `path` whose string field `key` is one of `wanted`, in file order, each
    checked to have `fields` and a non-empty string token; DatasetError naming the file and the record (its token,
    else `#line N`: where its `{` is in the file) when one is not."""
    required = frozenset(fields)
    scanned = _scan(path, key, wanted)
    if scanned is None:
        return [r for r in read_records(path, required) if isinstance(r.get(key), str) and r[key] in wanted]
    for record, offset in scanned:
        token = record.get("token")
        label = token if isinstance(token, str) and token else f"#line {_line_of(path, offset)}"
        check_fields(path, record, required, label)
        if not isinstance(token, str) or not token:
            detail = f"token must be a non-empty string, got {token!r}"
            raise DatasetError(detail, path=path, record=label, field="token")
    return [record for record, _ in scanned]


def _scan(path: Path, key: str, wanted: AbstractSet[str]) -> list[tuple[Record, int]] | None:
    """(record, byte offset) of every record whose `key` is one of `wanted`, found through the memory-mapped file;
    None when the file does not have the flat shape the scan relies on (see the module docstring). Values are
    compared as the file's bytes, so a value with an escape (a backslash) sends the table to the whole parse."""
    pattern = re.compile(rb'"' + re.escape(key.encode()) + rb'"\s*:\s*"([^"]*)"')
    wanted_bytes = {value.encode("utf-8") for value in wanted}
    try:
        with open(path, "rb") as handle:
            if os.fstat(handle.fileno()).st_size == 0:
                return None
            with mmap.mmap(handle.fileno(), 0, access=mmap.ACCESS_READ) as view:
                if not _is_one_list(view):
                    return None
                found = []
                for match in pattern.finditer(view):
                    raw = match.group(1)
                    if raw not in wanted_bytes:
                        if b"\\" in raw:  # an escape: the value may be another than these bytes spell
                            return None
                        continue
                    value = raw.decode("utf-8")
                    start = view.rfind(b"{", 0, match.start())
                    end = view.find(b"}", match.end())
                    record = _parse(view[start : end + 1]) if start >= 0 and end >= 0 else None
                    if record is None or record.get(key) != value:
                        return None
                    found.append((record, start))
                return found
    except FileNotFoundError:
        raise DatasetError("file not found", path=path) from None
    except OSError as exc:
        raise DatasetError(f"cannot read: {exc.strerror or exc}", path=path) from None


def _is_one_list(view: mmap.mmap) -> bool:
    """Whether the file's first and last non-blank bytes are `[` and `]`."""
    head = view[:64].lstrip()
    tail = view[max(0, len(view) - 64) :].rstrip()
    return head.startswith(b"[") and tail.endswith(b"]")


def _parse(text: bytes) -> Record | None:
    """One record cut out of the file, or None when it does not parse on its own as an object."""
    try:
        record = json.loads(text)
    except (ValueError, UnicodeDecodeError):
        return None
    return record if isinstance(record, dict) else None


def _line_of(path: Path, offset: int) -> int:
    """1-based line of the byte at `offset` (for error messages only: it reads the file up to there)."""
    with open(path, "rb") as handle:
        return handle.read(offset).count(b"\n") + 1
