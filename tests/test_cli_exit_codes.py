"""Exit codes of every `cama` command (cama_pipeline/console.py): 0 success, 1 a failure while working, 2 bad
input or options, with an `error:` line naming the file or option at fault.

Every registered command needs a bad-input case here: a new command without one fails
`test_every_command_has_a_bad_input_case`. Where a failure while working is cheap to cause, it is checked too.
"""

import gc
import socket
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from cama_pipeline.console import EXIT_BAD_INPUT, EXIT_FAILURE, EXIT_OK
from cama_pipeline.workspace import Workspace
from cama_studio.cli import app

runner = CliRunner()


def command_names() -> list[str]:
    """The names `cama` knows its commands by (typer's: the function name with dashes when not given)."""
    names = []
    for info in app.registered_commands:
        assert info.callback is not None
        names.append(info.name or info.callback.__name__.replace("_", "-"))
    return sorted(names)


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def bad_input_cases(tmp: Path) -> dict[str, tuple[list[str], str]]:
    """Per command: arguments with one bad input, and what its `error:` line must name (a path or an option).

    The stages after wigo read the workspace first (by default `<data set root's parent>/workspace`), so they
    name the workspace file they miss."""
    nowhere = str(tmp / "nowhere")
    corrupt = tmp / "corrupt.json"
    corrupt.write_text("{ not json", encoding="utf-8")
    workspace = Workspace(tmp / "workspace")
    sites_index = str(workspace.sites_index())
    return {
        "synth": (["--preset", "huge", "--out", str(tmp / "site")], "'huge'"),
        "eval": ([nowhere, str(corrupt), "--out", str(tmp / "report.json")], str(corrupt)),
        "export": ([str(corrupt), str(tmp / "release")], str(corrupt)),
        "import": ([nowhere, "--out", str(tmp / "set.json")], nowhere),
        "serve": ([str(tmp / "data"), "--review-url", "localhost:8080"], "CAMA_REVIEW_URL"),
        "demo": ([nowhere, "--data-dir", str(tmp / "server"), "--view-port", "0"], nowhere),
        "view": ([nowhere, "--port", str(free_port())], nowhere),
        "scenes": ([nowhere], nowhere),
        "wigo": ([nowhere], nowhere),
        "keyframes": ([nowhere], str(workspace.stage_dir("wigo"))),
        "sites": ([nowhere], nowhere),
        "pairs": ([nowhere], sites_index),
        "import-masks": (
            [nowhere, str(tmp / "masks"), "--class-map", "mapillary-vistas"],
            str(tmp / "masks"),
        ),
        "segment": ([nowhere], nowhere),
        "features": ([nowhere], sites_index),
        "sfm": ([nowhere], sites_index),
        "surface": ([nowhere], sites_index),
        "run": ([nowhere, "--stop-after", "wigo"], nowhere),
        "propose": ([nowhere, "--proposer", "rule", "--out", str(tmp / "p.json")], nowhere),
        "train": (["--registry", str(tmp / "registry"), "--bev-seeds", "x-y"], "--bev-seeds"),
        "train-masks": (["--registry", str(tmp / "masks"), "--site", nowhere], nowhere),
        "retrain": (
            ["--corrections", "no-equals-sign", "--val", nowhere, "--registry", str(tmp / "registry")],
            "--corrections",
        ),
        "vma-eval": ([nowhere, "--proposer", "rule", "--out", str(tmp / "eval.json")], nowhere),
        "vma-split": ([nowhere, "--out", str(tmp / "split.json")], nowhere),
        "train-segmenter": (["--sites", nowhere, "--out", str(tmp / "segmenter")], nowhere),
        "calibrate-segmenter": (["--sites", nowhere, "--out", str(tmp / "calibrated")], nowhere),
    }


def error_lines(output: str) -> list[str]:
    return [line for line in output.splitlines() if line.startswith("error:")]


def test_every_command_has_a_bad_input_case(tmp_path: Path) -> None:
    assert sorted(bad_input_cases(tmp_path)) == command_names()


@pytest.mark.parametrize("name", command_names())
def test_bad_input_exits_2_naming_the_file_or_option(name: str, tmp_path: Path) -> None:
    args, named = bad_input_cases(tmp_path)[name]
    result = runner.invoke(app, [name, *args])
    assert result.exit_code == EXIT_BAD_INPUT, result.output
    assert any(named in line for line in error_lines(result.output)), result.output


@pytest.mark.parametrize("name", command_names())
def test_usage_errors_exit_2_naming_the_option(name: str) -> None:
    result = runner.invoke(app, [name, "--no-such-option"])
    assert result.exit_code == EXIT_BAD_INPUT and "--no-such-option" in result.output, result.output


@pytest.mark.parametrize("name", command_names())
def test_help_exits_0(name: str) -> None:
    result = runner.invoke(app, [name, "--help"])
    assert result.exit_code == EXIT_OK, result.output


def test_a_bad_option_value_exits_2() -> None:
    result = runner.invoke(app, ["run", "data", "--executor", "cloud"])
    assert result.exit_code == EXIT_BAD_INPUT and any("--executor" in e for e in error_lines(result.output))
    result = runner.invoke(app, ["sfm", "data", "--workers", "0"])  # click's own range check
    assert result.exit_code == EXIT_BAD_INPUT and "--workers" in result.output


def test_run_exits_1_when_a_stage_breaks(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from cama_pipeline.sfm.errors import SfmError
    from cama_studio.pipeline import STAGES

    def broken_sfm() -> None:
        raise SfmError("every clip failed (scene-0001: no verified matches)")

    calls = {stage: (lambda: None) for stage in STAGES[:-1]} | {"sfm": broken_sfm}
    monkeypatch.setattr("cama_studio.pipeline._stage_calls", lambda *args: calls)
    result = runner.invoke(app, ["run", str(tmp_path), "--stop-after", "sfm"])
    assert result.exit_code == EXIT_FAILURE, result.output
    assert any("stage sfm failed" in e and "every clip failed" in e for e in error_lines(result.output))


def test_sfm_exits_1_when_every_clip_fails(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from cama_pipeline.sfm.errors import SfmError

    def every_clip_fails(*args: object, **kwargs: object) -> None:
        raise SfmError("every clip failed (scene-0001: no verified matches)")

    monkeypatch.setattr("cama_pipeline.sfm.command.run", every_clip_fails)
    result = runner.invoke(app, ["sfm", str(tmp_path)])
    assert result.exit_code == EXIT_FAILURE, result.output
    assert any("every clip failed" in e for e in error_lines(result.output))


def test_a_server_that_cannot_start_exits_1(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from uvicorn.config import STARTUP_FAILURE

    def port_taken(app: object, **kwargs: object) -> None:  # what uvicorn does when it cannot bind
        sys.exit(STARTUP_FAILURE)

    monkeypatch.setattr("uvicorn.run", port_taken)
    port = free_port()
    try:
        result = runner.invoke(app, ["serve", str(tmp_path / "data"), "--port", str(port)])
    finally:
        gc.unfreeze()  # `cama serve` freezes its start-up objects for the server's life
    assert result.exit_code == EXIT_FAILURE, result.output
    assert any(f"127.0.0.1:{port}" in e for e in error_lines(result.output))
