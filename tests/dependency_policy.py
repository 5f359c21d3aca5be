"""What a test does when something it needs is not installed: skip with the reason here, fail under CI.

`make test` installs every dependency of the test suite (the Python packages of requirements.lock, Debian's
PostgreSQL server programs and Chromium), so a missing one under CI means the install is broken, and a skip there
would hide it. Tests ask for what they need through `require_module`, `require_program` or `missing`: without CI
they skip with a reason naming the dependency; with `CI=true` they fail with the same message.

This module is also a pytest plugin (registered by tests/conftest.py), the safety net for a test that skips some
other way: under CI every skip, at collection or in a test, is reported as a failure with the skip's reason.
"""

import importlib
import os
import shutil
from collections.abc import Generator
from pathlib import Path
from types import ModuleType
from typing import NoReturn

import pytest

MAKE_TEST_INSTALLS_PACKAGES = "`make test` installs it: requirements.lock into .venv"
"""How the Python packages of the tests are installed."""


def under_ci() -> bool:
    """True when the environment says this is a CI run (`CI=true`, or 1 / yes, in any case)."""
    return os.environ.get("CI", "").strip().lower() in {"true", "1", "yes"}


def missing(what: str, install: str) -> NoReturn:
    """Skip the current test (or module) because `what` is not installed; under CI, fail instead.

    `install` says how `make test` installs it, so the message tells a reader how to get the test running.
    """
    message = f"missing dependency: {what} ({install})"
    if under_ci():
        pytest.fail(f"{message}; CI=true, so this fails instead of skipping", pytrace=False)
    pytest.skip(message, allow_module_level=True)


def require_module(name: str, install: str = MAKE_TEST_INSTALLS_PACKAGES) -> ModuleType:
    """The imported module `name`; `missing` when it cannot be imported (usable at module level)."""
    try:
        return importlib.import_module(name)
    except ImportError as error:
        missing(f"Python module {name!r} ({error})", install)


def require_program(program: str, why: str, install: str) -> Path:
    """The path of `program` (a path, or a name looked up on PATH); `missing` when it is not an executable file.

    `why` says what the tests need it for.
    """
    found = shutil.which(program)
    if found is None:
        missing(f"program {program} ({why})", install)
    return Path(found)


def _as_failure(report: pytest.TestReport | pytest.CollectReport) -> None:
    """Turn a skip report into a failure that keeps the skip's reason (xfail reports are left alone)."""
    if not (report.skipped and under_ci()) or hasattr(report, "wasxfail"):
        return
    longrepr = report.longrepr
    reason = longrepr[2].removeprefix("Skipped: ") if isinstance(longrepr, tuple) else str(longrepr)
    report.outcome = "failed"
    report.longrepr = f"skipped under CI=true, where nothing may skip: {reason}"


@pytest.hookimpl(wrapper=True)
def pytest_runtest_makereport(
    item: pytest.Item, call: pytest.CallInfo[None]
) -> Generator[None, pytest.TestReport, pytest.TestReport]:
    """Under CI, a test that skipped (in setup, call or teardown) is reported as failed."""
    report = yield
    _as_failure(report)
    return report


@pytest.hookimpl(wrapper=True)
def pytest_make_collect_report(
    collector: pytest.Collector,
) -> Generator[None, pytest.CollectReport, pytest.CollectReport]:
    """Under CI, a module that skipped while being collected (`pytest.importorskip`) is a collection error."""
    report = yield
    _as_failure(report)
    return report
