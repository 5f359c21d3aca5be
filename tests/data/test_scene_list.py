"""`cama scenes` lists what `load_dataset` would load, from the small tables only, filtered by location; bad
tables are named with exit 2."""

import json
import shutil
from pathlib import Path

from typer.testing import CliRunner

from cama_pipeline.data import load_dataset
from cama_pipeline.data.scene_list import scene_summaries
from cama_pipeline.data.schema import CAN_DIR, GNSS_MESSAGE, IMU_MESSAGE, WHEEL_MESSAGE, can_file_name
from cama_studio.cli import app
from tests.conftest import GeneratedSite
from tests.data.nuscenes_fixture import write_nuscenes_fixture


def test_the_list_agrees_with_the_loaded_data_set(tiny_site: GeneratedSite) -> None:
    root = tiny_site.result.out_dir / "nuscenes"
    loaded = load_dataset(root, check_files=False)
    listed = scene_summaries(root)
    assert [s.name for s in listed] == [s.name for s in loaded.scenes]
    for summary, scene in zip(listed, loaded.scenes, strict=True):
        assert summary.location == scene.location and summary.samples == len(scene.frames)
        assert summary.duration_s == (scene.frames[-1].timestamp_us - scene.frames[0].timestamp_us) / 1e6
        assert summary.description == scene.description
        can = scene.can
        present = {"ms_imu": can.imu, "zoe_veh_info": can.wheel, "gnss": can.gnss}
        assert set(summary.can_bus) == {name for name, series in present.items() if series is not None}
    assert scene_summaries(root, location=listed[0].location) == listed
    assert scene_summaries(root, location="no-such-city") == []


def test_cama_scenes_prints_lines_or_json(tiny_site: GeneratedSite) -> None:
    root = tiny_site.result.out_dir / "nuscenes"
    names = [s.name for s in scene_summaries(root)]
    runner = CliRunner()
    lines = runner.invoke(app, ["scenes", str(root)])
    assert lines.exit_code == 0, lines.output
    assert [line.split()[0] for line in lines.output.splitlines()[:-1]] == names
    assert lines.output.splitlines()[-1].startswith(f"{len(names)} scenes (")
    as_json = runner.invoke(app, ["scenes", str(root), "--json"])
    assert as_json.exit_code == 0 and [s["name"] for s in json.loads(as_json.output)] == names


def test_a_broken_log_link_or_a_missing_table_is_named(tmp_path: Path) -> None:
    fixture = write_nuscenes_fixture(tmp_path / "ds")
    fixture.edit_record("scene", fixture.scene_token, lambda r: r.update({"log_token": "no-such-log"}))
    runner = CliRunner()
    broken = runner.invoke(app, ["scenes", str(fixture.root)])
    assert broken.exit_code == 2
    assert "scene.json" in broken.output and "'log_token'" in broken.output and "no-such-log" in broken.output
    fixture.table_path("sample").unlink()
    missing = runner.invoke(app, ["scenes", str(fixture.root)])
    assert missing.exit_code == 2 and "sample.json" in missing.output


def test_a_scene_without_a_can_file_lists_what_it_has(tiny_site: GeneratedSite, tmp_path: Path) -> None:
    source = tiny_site.result.out_dir / "nuscenes"
    root = tmp_path / "nuscenes"
    for folder in (p for p in source.iterdir() if (p / "scene.json").is_file() or p.name == CAN_DIR):
        shutil.copytree(folder, root / folder.name)
    first = scene_summaries(root)[0].name
    (root / CAN_DIR / can_file_name(first, WHEEL_MESSAGE)).unlink()
    listed = {s.name: s.can_bus for s in scene_summaries(root)}
    assert WHEEL_MESSAGE not in listed[first] and IMU_MESSAGE in listed[first]
    assert all(WHEEL_MESSAGE in can for name, can in listed.items() if name != first)
    printed = CliRunner().invoke(app, ["scenes", str(root)])
    assert printed.exit_code == 0 and f"CAN {IMU_MESSAGE}+{GNSS_MESSAGE} " in printed.output
