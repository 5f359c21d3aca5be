"""`cama sfm` on the command line: runs the stage and prints each site; bad input exits with code 2."""

import shutil
from pathlib import Path

import pytest
from typer.testing import CliRunner

from cama_pipeline.workspace import Workspace
from cama_studio.cli import app

runner = CliRunner()


@pytest.fixture()
def workspace(sfm_inputs: object, tmp_path: Path) -> Path:
    return Path(shutil.copytree(sfm_inputs.workspace, tmp_path / "workspace"))  # type: ignore[attr-defined]


@pytest.mark.slow
def test_sfm_command_reconstructs_the_site(sfm_inputs: object, workspace: Path) -> None:
    args = ["sfm", str(sfm_inputs.dataset_root), "--workspace", str(workspace), "--preset", "rigid"]  # type: ignore[attr-defined]
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    assert "site-001" in result.output and "points" in result.output
    assert Workspace(workspace).sfm_report("site-001").is_file()
    again = runner.invoke(app, args)
    assert again.exit_code == 0 and "up to date" in again.output


def test_bad_input_exits_with_a_message(sfm_inputs: object, workspace: Path) -> None:
    root = str(sfm_inputs.dataset_root)  # type: ignore[attr-defined]
    bad_executor = runner.invoke(app, ["sfm", root, "--workspace", str(workspace), "--executor", "slurm"])
    assert bad_executor.exit_code == 2 and "executor" in bad_executor.output
    bad_preset = runner.invoke(app, ["sfm", root, "--workspace", str(workspace), "--preset", "fancy"])
    assert bad_preset.exit_code == 2 and "preset" in bad_preset.output
    shutil.rmtree(Workspace(workspace).stage_dir("features"))
    no_features = runner.invoke(app, ["sfm", root, "--workspace", str(workspace)])
    assert no_features.exit_code == 2 and "cama features" in no_features.output
