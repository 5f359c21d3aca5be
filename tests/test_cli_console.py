"""The CLI console (cama_pipeline/console.py): output that is not a terminal is never wrapped, whatever the
terminal width (COLUMNS), the path length or the machine; a terminal keeps rich's layout."""

import io
from pathlib import Path

import pytest
from rich.table import Table
from typer.testing import CliRunner

from cama_pipeline.console import PIPE_WIDTH, CliConsole
from cama_studio.cli import app

NARROW = {"COLUMNS": "40"}


@pytest.fixture()
def deep_dir(tmp_path: Path) -> Path:
    """A folder whose path is more than 200 characters long (tests/vma/test_vma_cli.py has a success line's case)."""
    deep = tmp_path.joinpath(*(f"{'nested-folder-' * 4}{i}" for i in range(4)))
    deep.mkdir(parents=True)
    assert len(str(deep)) > 200
    return deep


def test_a_long_error_stays_on_one_line_in_a_narrow_terminal(deep_dir: Path) -> None:
    missing = deep_dir / "no-such-dataset"
    result = CliRunner().invoke(app, ["wigo", str(missing)], env=NARROW)
    assert result.exit_code == 2
    assert any(line.startswith("error:") and str(missing) in line for line in result.output.splitlines())


def test_output_that_is_not_a_terminal_is_not_wrapped(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("COLUMNS", "40")
    console = CliConsole(file=io.StringIO())
    text = " ".join(["word"] * 100)
    console.print(text)
    table = Table("site", "path")
    table.add_row("site-001", "x" * 120)
    console.print(table)
    lines = console.file.getvalue().splitlines()  # type: ignore[attr-defined]
    assert lines[0] == text
    assert "x" * 120 in "\n".join(lines[1:])  # laid out PIPE_WIDTH wide, not folded at 40
    assert console.width == PIPE_WIDTH


def test_a_terminal_keeps_rich_layout() -> None:
    console = CliConsole(file=io.StringIO(), force_terminal=True, width=40, color_system=None)
    console.print(" ".join(["word"] * 20))
    assert all(len(line) <= 40 for line in console.file.getvalue().splitlines())  # type: ignore[attr-defined]
    assert console.width == 40
