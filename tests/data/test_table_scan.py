"""`select_records` finds the wanted records of a large table without parsing the rest, and falls back to parsing
the whole file whenever the file does not have the flat shape it relies on: either way it returns what a whole
parse and a filter return, and reports bad input by file and record."""

import json
from pathlib import Path
from typing import Any

import pytest

from cama_pipeline.data import DatasetError
from cama_pipeline.data.table_scan import select_records

FIELDS = ("token", "sample_token", "filename")


def records(n: int = 30) -> list[dict[str, Any]]:
    """Flat records, three per sample, some with lists as values (as ego_pose's translation)."""
    return [
        {
            "token": f"sd-{i}",
            "sample_token": f"sample-{i // 3}",
            "filename": f"samples/CAM_FRONT/{i}.jpg",
            "translation": [float(i), 0.5, -1e-3],
        }
        for i in range(n)
    ]


def write(path: Path, rows: list[dict[str, Any]], **dumps: Any) -> Path:
    path.write_text(json.dumps(rows, **dumps))
    return path


def wanted_by_filter(rows: list[dict[str, Any]], wanted: set[str]) -> list[dict[str, Any]]:
    return [r for r in rows if r["sample_token"] in wanted]


@pytest.mark.parametrize("dumps", [{}, {"indent": 0}, {"indent": 2}, {"separators": (",", ":")}])
def test_selection_equals_a_whole_parse_filtered(tmp_path: Path, dumps: dict[str, Any]) -> None:
    rows = records()
    path = write(tmp_path / "sample_data.json", rows, **dumps)
    wanted = {"sample-2", "sample-7", "sample-no-such"}
    assert select_records(path, FIELDS, "sample_token", wanted) == wanted_by_filter(rows, wanted)


@pytest.mark.parametrize(
    "edit",
    [
        {"filename": "samples/{CAM_FRONT}/odd.jpg"},  # braces inside a string: the record cannot be cut out
        {"extra": {"nested": "object"}},  # a nested object: neither
        {"filename": 'samples/"quoted".jpg'},  # an escaped quote in another field
        {"sample_token": 'sample-"2"'},  # escapes in the key's own value
        {"sample_token": "sample-\u00e9"},  # a non-ASCII value
    ],
)
def test_awkward_records_come_out_as_a_whole_parse_gives_them(tmp_path: Path, edit: dict[str, Any]) -> None:
    rows = records()
    rows[7].update(edit)  # one of sample-2's records
    for ascii_only in (True, False):
        path = write(tmp_path / "sample_data.json", rows, indent=0, ensure_ascii=ascii_only)
        wanted = {"sample-2", "sample-5", 'sample-"2"', "sample-\u00e9"}
        selected = select_records(path, FIELDS, "sample_token", wanted)
        assert selected == wanted_by_filter(rows, wanted)


def test_a_truncated_file_is_reported_by_line_and_column(tmp_path: Path) -> None:
    text = json.dumps(records(), indent=0)
    path = tmp_path / "ego_pose.json"
    path.write_text(text[: len(text) // 2])
    with pytest.raises(DatasetError, match=r"ego_pose\.json.*line \d+, column \d+"):
        select_records(path, FIELDS, "sample_token", {"sample-1"})


def test_a_selected_record_missing_a_field_is_named(tmp_path: Path) -> None:
    rows = records()
    del rows[4]["filename"]
    path = write(tmp_path / "sample_data.json", rows, indent=0)
    with pytest.raises(
        DatasetError, match=r"sample_data\.json: record 'sd-4', field 'filename': missing field"
    ):
        select_records(path, FIELDS, "sample_token", {"sample-1"})
    # a record that is not selected is not read, so its missing field does not matter
    assert len(select_records(path, FIELDS, "sample_token", {"sample-2"})) == 3


def test_a_selected_record_without_a_token_is_named_by_its_line(tmp_path: Path) -> None:
    rows = records(4)
    del rows[2]["token"]
    path = write(tmp_path / "sample_data.json", rows, indent=0)
    # indent=0: every record opens on a line of its own
    lines = [n + 1 for n, text in enumerate(path.read_text().splitlines()) if text == "{"]
    with pytest.raises(DatasetError, match=rf"record #line {lines[2]}, field 'token'"):
        select_records(path, ("sample_token",), "sample_token", {"sample-0", "sample-1"})


def test_missing_and_empty_files(tmp_path: Path) -> None:
    with pytest.raises(DatasetError, match="file not found"):
        select_records(tmp_path / "nothing.json", FIELDS, "sample_token", {"sample-1"})
    (tmp_path / "empty.json").write_text("")
    with pytest.raises(DatasetError, match=r"empty\.json.*invalid JSON"):
        select_records(tmp_path / "empty.json", FIELDS, "sample_token", {"sample-1"})
