"""`read_table(..., keep=...)`: a flat table read whole keeps only the fields asked for, and every record is still
checked for all of its table's fields before the others are dropped."""

import json
from pathlib import Path

import pytest

from cama_pipeline.data.errors import DatasetError
from cama_pipeline.data.schema import TABLE_FIELDS
from cama_pipeline.data.tables import read_table


def _sample_data(index: int) -> dict[str, object]:
    record: dict[str, object] = {field: f"{field}-{index}" for field in TABLE_FIELDS["sample_data"]}
    record.update({"token": f"sd-{index}", "timestamp": 1000 + index, "is_key_frame": index % 2 == 0})
    return record


def _write(tmp_path: Path, records: list[dict[str, object]]) -> Path:
    (tmp_path / "sample_data.json").write_text(json.dumps(records, indent=0))
    return tmp_path


def test_only_the_kept_fields_remain_in_file_order(tmp_path: Path) -> None:
    version_dir = _write(tmp_path, [_sample_data(i) for i in range(3)])
    table = read_table(version_dir, "sample_data", keep=("ego_pose_token", "is_key_frame"))
    assert list(table) == ["sd-0", "sd-1", "sd-2"]
    assert table["sd-1"] == {"token": "sd-1", "ego_pose_token": "ego_pose_token-1", "is_key_frame": False}
    assert read_table(version_dir, "sample_data")["sd-1"] == _sample_data(1)


@pytest.mark.parametrize("dropped", ["filename", "ego_pose_token"])
def test_a_record_missing_a_field_is_named_whether_kept_or_not(tmp_path: Path, dropped: str) -> None:
    records = [_sample_data(i) for i in range(3)]
    del records[1][dropped]
    version_dir = _write(tmp_path, records)
    with pytest.raises(DatasetError, match=rf"sample_data.json.*'sd-1'.*'{dropped}'"):
        read_table(version_dir, "sample_data", keep=("ego_pose_token",))
