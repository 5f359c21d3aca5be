"""The tables the loader needs, cut to what it keeps: camera images, optionally of some scenes only.

The loader uses only camera sample_data and their ego poses: of the two large tables (2.6 million records each in
nuScenes v1.0-trainval) it keeps the sample_data records not of a lidar or radar sensor (so a record naming no
known sensor still reaches the link check) and the ego_pose records those use. With scenes named, the two are read
through `table_scan.select_records` (sample_data by sample, ego_pose by token), which parses only those records;
without, they are parsed whole, which is quicker when most of the file is wanted (one `json.load` shares its key
strings between records; records parsed one by one each hold their own). The small tables are read whole.
"""

from collections.abc import Sequence
from pathlib import Path

from cama_pipeline.data.errors import DatasetError
from cama_pipeline.data.schema import CAMERA_MODALITY, REQUIRED_TABLES, TABLE_FIELDS
from cama_pipeline.data.table_scan import select_records
from cama_pipeline.data.tables import Table, index_by_token, read_records, read_tables, table_path

LARGE_TABLES = ("sample_data", "ego_pose")
SHOWN_SCENE_NAMES = 12
"""How many of the data set's scene names an unknown-scene error lists."""


def read_camera_tables(version_dir: Path, scenes: Sequence[str] | None = None) -> dict[str, Table]:
    """The required tables of `version_dir`, indexed by token: sample_data cut to camera records and ego_pose to
    the records they use; with `scenes` (names), scene, sample and sample_data cut to those scenes as well.
    DatasetError naming the table (and scene names) when one is missing or a name is unknown."""
    for name in LARGE_TABLES:
        path = table_path(version_dir, name)
        if not path.is_file():
            raise DatasetError(f"required table {name!r} is missing", path=path)
    tables = read_tables(version_dir, [n for n in REQUIRED_TABLES if n not in LARGE_TABLES])
    if scenes is not None:
        tables["scene"] = named_scenes(version_dir, tables["scene"], scenes)
        tables["sample"] = {
            token: record
            for token, record in tables["sample"].items()
            if record["scene_token"] in tables["scene"]
        }
    other = non_camera_sensors(tables)
    sample_data_path = table_path(version_dir, "sample_data")
    fields = TABLE_FIELDS["sample_data"]
    if scenes is None:
        found = read_records(sample_data_path, fields)
    else:
        found = select_records(sample_data_path, fields, "sample_token", tables["sample"].keys())
    records = [r for r in found if not _named_in(r, "calibrated_sensor_token", other)]
    tables["sample_data"] = index_by_token(sample_data_path, records)
    used = {r["ego_pose_token"] for r in records if isinstance(r["ego_pose_token"], str)}
    ego_pose_path = table_path(version_dir, "ego_pose")
    if scenes is None:
        poses = [
            r for r in read_records(ego_pose_path, TABLE_FIELDS["ego_pose"]) if _named_in(r, "token", used)
        ]
    else:
        poses = select_records(ego_pose_path, TABLE_FIELDS["ego_pose"], "token", used)
    tables["ego_pose"] = index_by_token(ego_pose_path, poses)
    return tables


def named_scenes(version_dir: Path, scene_table: Table, names: Sequence[str]) -> Table:
    """The records of scene.json named `names`, in file order; DatasetError listing unknown names and some known."""
    wanted = set(names)
    chosen = {token: r for token, r in scene_table.items() if r.get("name") in wanted}
    found = {r["name"] for r in chosen.values()}
    missing = [n for n in dict.fromkeys(names) if n not in found]
    if missing:
        known = [str(r.get("name")) for r in scene_table.values()]
        shown = ", ".join(known[:SHOWN_SCENE_NAMES]) + (" ..." if len(known) > SHOWN_SCENE_NAMES else "")
        raise DatasetError(
            f"no scene named {', '.join(map(repr, missing))}; the data set has {len(known)} scenes: {shown}",
            path=table_path(version_dir, "scene"),
            field="name",
        )
    return chosen


def non_camera_sensors(tables: dict[str, Table]) -> set[str]:
    """calibrated_sensor tokens of known sensors that are not cameras (lidar, radar)."""
    other = {
        token
        for token, sensor in tables["sensor"].items()
        if isinstance(sensor["modality"], str) and sensor["modality"] != CAMERA_MODALITY
    }
    return {token for token, record in tables["calibrated_sensor"].items() if record["sensor_token"] in other}


def _named_in(record: dict[str, object], field: str, tokens: set[str]) -> bool:
    """Whether the record's `field` is a string among `tokens` (a value of another type never is)."""
    value = record[field]
    return isinstance(value, str) and value in tokens
