"""The `cama eval` command function and the input readers: good runs and clear errors (exit code 2)."""

import json
from pathlib import Path

import pytest
import typer
from typer.testing import CliRunner

from cama_pipeline.evaluate.command import eval_command
from cama_pipeline.evaluate.inputs import EvaluationInputError, load_true_poses, load_vector_map

app = typer.Typer()
app.command("eval")(eval_command)
app.command("noop")(lambda: None)  # keeps `eval` a sub-command, as in the real CLI
runner = CliRunner()


def write_map(path: Path, elements: object) -> Path:
    """Write a vector map JSON file."""
    path.write_text(json.dumps({"elements": elements}))
    return path


GOOD = [
    {"id": "d1", "class": "divider", "points": [[1.0, 0.0, 0.0], [30.0, 0.0, 0.0]]},
    {"id": "b1", "class": "boundary", "points": [[1.0, 5.0], [30.0, 5.0]]},
]


def test_reads_3d_and_2d_elements(tmp_path: Path) -> None:
    elements = load_vector_map(write_map(tmp_path / "m.json", GOOD))
    assert [e.has_elevation for e in elements] == [True, False]


def test_eval_runs_and_writes_report(tmp_path: Path, small_dataset) -> None:
    out = tmp_path / "report.json"
    vector_map = write_map(tmp_path / "m.json", GOOD)
    result = runner.invoke(
        app, ["eval", str(small_dataset.root), str(vector_map), "--out", str(out), "--boundaries"]
    )
    assert result.exit_code == 0, result.output
    report = json.loads(out.read_text())
    assert report["overall"]["images"] == 2 * 6
    assert len(report["per_camera"]) == 6 and "config" in report


@pytest.mark.parametrize(
    "elements, message",
    [
        (
            [{"id": "x", "class": "lane", "points": [[0, 0], [1, 1]]}],
            r"elements\[0\]\.class: unknown class 'lane'",
        ),
        ([{"id": "x", "class": "divider", "points": [[0, 0]]}], r"elements\[0\]\.points"),
        ([{"id": "x", "class": "divider", "points": [[0, 0], [1, None]]}], "finite numbers"),
        ([{"id": "x", "class": "divider", "points": [[0, 0], [1, 1, 1]]}], "same number"),
        ([GOOD[0], GOOD[0]], "duplicate id"),
    ],
)
def test_bad_map_is_named(tmp_path: Path, elements: object, message: str) -> None:
    path = write_map(tmp_path / "bad.json", elements)
    with pytest.raises(EvaluationInputError, match=message):
        load_vector_map(path)


def test_bad_json_and_missing_file(tmp_path: Path) -> None:
    broken = tmp_path / "broken.json"
    broken.write_text("{not json")
    with pytest.raises(EvaluationInputError, match="broken.json: not valid JSON"):
        load_vector_map(broken)
    with pytest.raises(FileNotFoundError, match="nope.json"):
        load_vector_map(tmp_path / "nope.json")
    poses = tmp_path / "poses.json"
    poses.write_text(json.dumps({"tok": {"translation": [0, 0]}}))
    with pytest.raises(EvaluationInputError, match="pose 'tok'"):
        load_true_poses(poses)


@pytest.mark.parametrize(
    "case", ["missing_map", "bad_class", "true_without_path", "missing_dataset", "unknown_scene"]
)
def test_command_errors_exit_2(tmp_path: Path, small_dataset, case: str) -> None:
    good = write_map(tmp_path / "m.json", GOOD)
    args = {
        "missing_map": [str(small_dataset.root), str(tmp_path / "missing.json")],
        "bad_class": [
            str(small_dataset.root),
            str(write_map(tmp_path / "bad.json", [{"class": "x", "points": []}])),
        ],
        "true_without_path": [str(small_dataset.root), str(good), "--poses", "true"],
        "missing_dataset": [str(tmp_path / "no_dataset"), str(good)],
        "unknown_scene": [str(small_dataset.root), str(good), "--scene", "scene-9999"],
    }[case]
    result = runner.invoke(app, ["eval", *args, "--out", str(tmp_path / "r.json")])
    assert result.exit_code == 2, result.output
    assert "error:" in result.output
    assert not (tmp_path / "r.json").exists()
