"""Reading the JSON tables of a nuScenes-layout data set: existence, JSON syntax, fields, unique tokens."""

import itertools
import json
import logging
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

from cama_pipeline.data.errors import DatasetError
from cama_pipeline.data.schema import OPTIONAL_TABLES, REQUIRED_TABLES, TABLE_FIELDS

logger = logging.getLogger(__name__)

Record = dict[str, Any]
"""One record of a table, as parsed from JSON."""
Table = dict[str, Record]
"""A table indexed by token, in file order."""


def table_path(version_dir: Path, name: str) -> Path:
    """Path of table `name` (e.g. `sample_data`) in a version folder."""
    return Path(version_dir) / f"{name}.json"


def read_json(path: Path, object_hook: Callable[[dict[str, Any]], Any] | None = None) -> Any:
    """Parse a JSON file (each object through `object_hook` when given, as `json.load` does); any failure becomes
    a DatasetError naming the file (and line/column for syntax)."""
    try:
        with open(path, encoding="utf-8") as handle:
            return json.load(handle, object_hook=object_hook)
    except FileNotFoundError:
        raise DatasetError("file not found", path=path) from None
    except json.JSONDecodeError as exc:
        raise DatasetError(
            f"invalid JSON at line {exc.lineno}, column {exc.colno}: {exc.msg}", path=path
        ) from None
    except UnicodeDecodeError as exc:
        raise DatasetError(f"not UTF-8 text (byte offset {exc.start})", path=path) from None
    except OSError as exc:
        raise DatasetError(f"cannot read: {exc.strerror or exc}", path=path) from None


def read_records(path: Path, fields: Iterable[str], keep: Iterable[str] | None = None) -> list[Record]:
    """Read a JSON list of dicts and check each has `fields`; errors name the record (token or index).
    `keep`: only these fields of each record are kept, the others dropped as the file is parsed (for a flat
    table read whole, e.g. nuScenes trainval's 1.3 GB sample_data.json, of which a reader needs a few fields)."""
    required = frozenset(fields)
    data = read_json(path, None if keep is None else _projection(path, required, tuple(keep)))
    if not isinstance(data, list):
        raise DatasetError(f"expected a JSON list of records, got {type(data).__name__}", path=path)
    if keep is not None:
        required = required & frozenset(keep)  # the rest was checked before it was dropped
    for index, record in enumerate(data):
        if not isinstance(record, dict):
            raise DatasetError(
                f"expected a JSON object, got {type(record).__name__}", path=path, record=f"#{index}"
            )
        check_fields(path, record, required, record_label(record, index))
    return data


def _projection(path: Path, required: frozenset[str], keep: tuple[str, ...]) -> Callable[[Record], Record]:
    """A `json.load` object hook that checks each object (a record of a flat table: objects come in file order)
    has `required` and keeps only the fields in `keep`."""
    index = itertools.count()

    def project(record: Record) -> Record:
        check_fields(path, record, required, record_label(record, next(index)))
        return {name: record[name] for name in keep if name in record}

    return project


def check_fields(path: Path, record: Record, required: frozenset[str], label: str) -> None:
    """DatasetError naming the record (`label`) and its first missing field when it lacks one of `required`."""
    if not required <= record.keys():
        missing = sorted(required - record.keys())
        raise DatasetError(
            "missing field" if len(missing) == 1 else f"missing fields {missing}",
            path=path,
            record=label,
            field=missing[0],
        )


def record_label(record: Record, index: int) -> str:
    """How an error names a record: its token when it has a string one, else `#<index>` in the file."""
    token = record.get("token")
    return token if isinstance(token, str) and token else f"#{index}"


def index_by_token(path: Path, records: list[Record]) -> Table:
    """Index records by their `token` (non-empty string, unique in the table)."""
    table: Table = {}
    first_index: dict[str, int] = {}
    for index, record in enumerate(records):
        token = record.get("token")
        if not isinstance(token, str) or not token:
            raise DatasetError(
                f"token must be a non-empty string, got {token!r}",
                path=path,
                record=f"#{index}",
                field="token",
            )
        if token in table:
            raise DatasetError(
                f"duplicate token (records #{first_index[token]} and #{index})",
                path=path,
                record=token,
                field="token",
            )
        table[token] = record
        first_index[token] = index
    return table


def read_table(version_dir: Path, name: str, keep: Iterable[str] | None = None) -> Table:
    """Read one table indexed by token; a missing optional table is empty, a missing required one an error.
    `keep`: only these fields of each record (`read_records`; "token" is always kept)."""
    if name not in REQUIRED_TABLES and name not in OPTIONAL_TABLES:
        raise ValueError(f"unknown table {name!r}; known: {sorted(REQUIRED_TABLES + OPTIONAL_TABLES)}")
    path = table_path(version_dir, name)
    if not path.is_file():
        if name in REQUIRED_TABLES:
            raise DatasetError(f"required table {name!r} is missing", path=path)
        logger.debug("optional table %s absent: treated as empty", path)
        return {}
    kept = None if keep is None else ("token", *(field for field in keep if field != "token"))
    records = read_records(path, TABLE_FIELDS.get(name, ("token",)), kept)
    table = index_by_token(path, records)
    logger.debug("read %d records from %s", len(table), path)
    return table


def read_tables(version_dir: Path, names: Iterable[str] = REQUIRED_TABLES) -> dict[str, Table]:
    """Read several tables of one version folder, keyed by table name."""
    return {name: read_table(version_dir, name) for name in names}
