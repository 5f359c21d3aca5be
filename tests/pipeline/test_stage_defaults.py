"""Every stage command, run with its defaults, calls its stage exactly as `cama run` does.

A user who runs `cama wigo`, `cama keyframes`, ... `cama propose` one by one must get what `cama run` makes. Each
stage's `run` (and `propose`) is replaced by a recorder; the pipeline and then each command are driven with their
defaults, and the recorded calls, bound to the real signature with its defaults applied (a config left None
as its default config), must be equal.
"""

import dataclasses
import importlib
import inspect
import typing
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from typer.testing import CliRunner

from cama_pipeline.site.io import write_sites_index
from cama_pipeline.workspace import Workspace
from cama_studio import pipeline
from cama_studio.cli import app
from models.vma.propose import ProposeResult

STAGE_PACKAGES = {
    "wigo": "cama_pipeline.wigo",
    "keyframes": "cama_pipeline.keyframes",
    "sites": "cama_pipeline.site",
    "pairs": "cama_pipeline.pairs",
    "segment": "cama_pipeline.segment",
    "features": "cama_pipeline.features",
    "sfm": "cama_pipeline.sfm",
    "surface": "cama_pipeline.surface",
}
"""Stage name (also its `cama` command) -> the package whose `stage.run` it calls from `command.py`."""


class _Recorded(Exception):
    """Raised by a recorder in command mode: the call is recorded, the command need not go on."""


class Recorder:
    """Stands in for a stage's `run`: records its arguments bound to the real signature, defaults applied."""

    def __init__(self, real: Callable[..., Any], returns: Any = None) -> None:
        self.signature = inspect.signature(real)
        self.hints = typing.get_type_hints(real)
        self.returns = returns
        self.calls: list[dict[str, Any]] = []
        self.stop = False

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        bound = self.signature.bind(*args, **kwargs)
        bound.apply_defaults()
        arguments = {
            name: _default_config(self.hints.get(name), value) for name, value in bound.arguments.items()
        }
        self.calls.append({name: _comparable(value) for name, value in arguments.items()})
        if self.stop:
            raise _Recorded
        return self.returns


def _default_config(annotation: Any, value: Any) -> Any:
    """A config argument left None (`X | None`, None meaning `X()`) as that default config: `cama run` passes every
    stage its effective configs (`merge_config=MergeConfig()`, `inference=InferenceConfig()`), a command may
    leave them None, and both mean the same call."""
    configs = [
        a
        for a in typing.get_args(annotation)
        if dataclasses.is_dataclass(a) and a.__name__.endswith("Config")
    ]
    return configs[0]() if value is None and len(configs) == 1 else value


def _comparable(value: Any) -> Any:
    """Paths compared resolved, whether given as str or Path."""
    return Path(value).resolve() if isinstance(value, Path | str) and "/" in str(value) else value


def _patch(monkeypatch: pytest.MonkeyPatch, module: str, name: str, recorder: Recorder) -> None:
    monkeypatch.setattr(importlib.import_module(module), name, recorder)


def test_every_stage_command_defaults_to_what_cama_run_does(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    dataset, workspace = tmp_path / "nuscenes", tmp_path / "workspace"
    dataset.mkdir()
    write_sites_index(Workspace(workspace).sites_index(), {"sites": [{"site_id": "site-001"}], "dropped": []})
    recorders: dict[str, Recorder] = {}
    for stage, package in STAGE_PACKAGES.items():
        recorders[stage] = Recorder(importlib.import_module(f"{package}.stage").run)
        for module in (package, f"{package}.stage", f"{package}.command"):
            if hasattr(importlib.import_module(module), "run"):
                _patch(monkeypatch, module, "run", recorders[stage])
    proposed = ProposeResult(tmp_path / "p.json", 0, 0.0, skipped=True, checkpoint=None)
    recorders["propose"] = Recorder(importlib.import_module("models.vma.propose").propose, returns=proposed)
    _patch(monkeypatch, "models.vma.propose", "propose", recorders["propose"])
    _patch(monkeypatch, "models.vma.commands", "propose", recorders["propose"])

    pipeline.run(dataset, workspace, stop_after="propose")
    assert all(len(r.calls) == 1 for r in recorders.values()), {s: len(r.calls) for s, r in recorders.items()}

    runner = CliRunner()
    commands = {stage: [stage, str(dataset), "--workspace", str(workspace)] for stage in STAGE_PACKAGES}
    commands["propose"] = [
        "propose",
        str(Workspace(workspace).surface_bev("site-001")),
        "--out",
        str(Workspace(workspace).proposals("site-001")),
    ]
    for stage, argv in commands.items():
        recorder = recorders[stage]
        recorder.stop = True
        result = runner.invoke(app, argv)
        assert isinstance(result.exception, _Recorded), (stage, result.output, result.exception)
        from_pipeline, from_command = recorder.calls
        assert from_command == from_pipeline, f"`cama {stage}` defaults differ from `cama run`"
