"""The nuScenes-CAMAv2 export writes its two large files (ego_pose.json, pose_sources.json: 2.6 million records
each on nuScenes trainval) as they are produced: the text must be exactly what `json.dumps` of the whole would be,
in the source's layout."""

import json
from pathlib import Path
from typing import Any

import pytest

from annotations.nuscenes_cama_poses import (
    EgoPoseEntry,
    json_layout,
    json_list_chunks,
    pose_source_record,
    pose_sources_chunks,
    pose_sources_header,
)
from cama_pipeline.data import Pose

RECORDS: list[dict[str, Any]] = [
    {"token": f"t{i}", "timestamp": i, "rotation": [1.0, 0.0, 0.0, 0.0], "translation": [i, 2.5, {"z": None}]}
    for i in range(7)
]


@pytest.mark.parametrize("indent", [None, 0, 1, 4])
@pytest.mark.parametrize("batch", [1, 3, 100])
@pytest.mark.parametrize("count", [0, 1, 7])
def test_list_chunks_are_json_dumps_of_the_whole(indent: int | None, batch: int, count: int) -> None:
    records = RECORDS[:count]
    assert "".join(json_list_chunks(iter(records), indent, batch=batch)) == json.dumps(records, indent=indent)


@pytest.mark.parametrize("count", [0, 1, 3])
def test_pose_sources_chunks_are_json_dumps_of_the_whole(count: int) -> None:
    pose = Pose([1.0, 2.0, 3.0], [1.0, 0.0, 0.0, 0.0])
    kinds = [
        EgoPoseEntry("sfm", pose, "sd-0", "CAM_FRONT", camera=True),
        EgoPoseEntry("wigo+sfm", pose, "sd-1", "LIDAR_TOP", correction_from="sd-0"),
        EgoPoseEntry("coarse", None, None, None),
    ]
    entries = {f"ep-{i}": kinds[i] for i in range(count)}
    header = pose_sources_header(entries, version="v-cama", source_version="v", max_borrow_gap_us=500_000)
    whole = {**header, "ego_poses": {token: pose_source_record(entry) for token, entry in entries.items()}}
    text = "".join(pose_sources_chunks(header, entries))
    assert text == json.dumps(whole, indent=1)
    assert json.loads(text)["counts"]["coarse"] == (1 if count == 3 else 0)


@pytest.mark.parametrize("indent", [None, 0, 2])
@pytest.mark.parametrize("newline", [False, True])
def test_the_layout_is_read_from_the_files_ends(tmp_path: Path, indent: int | None, newline: bool) -> None:
    path = tmp_path / "ego_pose.json"
    path.write_text(json.dumps(RECORDS * 2000, indent=indent) + ("\n" if newline else ""))  # > 64 KiB a line
    assert json_layout(path) == (indent, newline)
