"""Spies on the lint module shared by the lint tests: count a rule's calls, refuse the per-vertex GEOS walks.

Both the backend test of the probe's site and the incremental-lint test check work by counting calls, never by
time, so they do not depend on the machine's load."""

import importlib
from collections.abc import Callable
from typing import Any

import pytest
import shapely

lint_module = importlib.import_module("app.backend.quality.lint")  # the package's `lint` is the function

VERTEX_WALKS = ("line_interpolate_point", "line_locate_point", "node")
"""shapely functions that walk every vertex of a line per call: what made the probe's site lint for 30 s."""


def _refuse(*_args: object, **_kwargs: object) -> None:
    raise AssertionError("a per-vertex GEOS walk was called")


def refuse_vertex_walks(monkeypatch: pytest.MonkeyPatch) -> None:
    """Make every per-vertex GEOS walk fail the test if the lint calls it."""
    for name in VERTEX_WALKS:
        monkeypatch.setattr(shapely, name, _refuse)


def count_calls(monkeypatch: pytest.MonkeyPatch, name: str) -> list[int]:
    """Count the calls of one rule function of the lint module (the count is `[0]` of the returned list)."""
    calls = [0]
    original: Callable[..., Any] = getattr(lint_module, name)

    def counted(*args: Any, **kwargs: Any) -> Any:
        calls[0] += 1
        return original(*args, **kwargs)

    monkeypatch.setattr(lint_module, name, counted)
    return calls
