"""Retrain progress: the child's step log records become a progress file, and the job's progress and message; a
cancelled child ends even when SIGTERM does not end it; a hung child is stopped and the job fails saying so, and a
busy one is left to work."""

import json
import logging
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from app.backend.jobs.process_cpu import tree_cpu_seconds
from app.backend.jobs.runner import JobCancelled
from app.backend.jobs.vma import FIT_SPAN, StepReporter, _run_child, read_step, step_progress


def emit_step(logger: logging.Logger, step: int, total: int, loss: float) -> None:
    """A record as `models.vma.train.fit` logs it."""
    logger.info("step %d/%d loss %.4f %s", step, total, loss, {"class": 0.1})


def test_step_records_become_the_progress_file(tmp_path: Path) -> None:
    path = tmp_path / "progress.json"
    logger = logging.getLogger("test.retrain.steps")
    logger.setLevel(logging.INFO)
    handler = StepReporter(path)
    logger.addHandler(handler)
    try:
        logger.info("starting %s", "now")  # not a step record: ignored
        assert read_step(path) is None
        emit_step(logger, 51, 300, 0.4125)
        assert read_step(path) == {"step": 51, "total": 300, "loss": 0.4125}
        emit_step(logger, 101, 300, 0.25)
        assert read_step(path) == {"step": 101, "total": 300, "loss": 0.25}
    finally:
        logger.removeHandler(handler)


def test_progress_follows_the_steps() -> None:
    progress, message = step_progress(None, 3.0)
    assert progress == FIT_SPAN[0] and "evaluating the current model" in message
    progress, message = step_progress({"step": 150, "total": 300, "loss": 0.5}, 12.0)
    assert progress == (FIT_SPAN[0] + FIT_SPAN[1]) / 2
    assert "step 150/300, loss 0.5000" in message and "candidate" not in message
    progress, message = step_progress({"step": 300, "total": 300, "loss": 0.2}, 20.0)
    assert progress == FIT_SPAN[1] and message.endswith("evaluating the candidate")


def test_unreadable_progress_file_reads_as_no_step(tmp_path: Path) -> None:
    path = tmp_path / "progress.json"
    path.write_text("{not json")
    assert read_step(path) is None
    path.write_text('{"step": 3}')
    assert read_step(path) is None


def sigterm_ignoring_child(out: Path) -> None:
    """A retraining child that SIGTERM does not end, as one deadlocked with it blocked in CPython's resource
    tracker was (ignored here, which holds in every thread of the child)."""
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    out.with_name("child_started").touch()
    time.sleep(120)


class CancelOnceStarted:
    """The job context of a job whose cancel is asked for once the child has started."""

    def __init__(self, started: Path) -> None:
        self.started = started

    def report(self, progress: float, message: str | None = None, *, force: bool = False) -> None:
        if self.started.is_file():
            raise JobCancelled("cancel requested")


def test_a_cancelled_child_that_sigterm_does_not_end_is_killed(tmp_path: Path) -> None:
    out = tmp_path / "retrain.json"
    context = CancelOnceStarted(tmp_path / "child_started")
    began = time.monotonic()
    with pytest.raises(JobCancelled):
        _run_child(context, (), out, target=sigterm_ignoring_child)  # type: ignore[arg-type]
    assert time.monotonic() - began < 100  # killed after the grace, not left to sleep its 120 s
    assert not out.exists()


class Quiet:
    """The job context of a job nobody cancels."""

    def report(self, progress: float, message: str | None = None, *, force: bool = False) -> None:
        pass


def hung_child(out: Path) -> None:
    """A retraining child that hangs: it waits and uses no CPU, as the deadlocked one did."""
    out.with_name("child_started").touch()
    time.sleep(120)


def busy_child(out: Path) -> None:
    """A child that computes for 3 s of CPU (however long the machine takes to give them) and then reports its
    result: slow, not hung."""
    total = 0
    while time.process_time() < 3.0:
        total += sum(range(1000))
    out.write_text(json.dumps({"candidate": "v0002", "promoted": False, "work": total}))


def test_a_hung_child_is_stopped_and_the_job_fails_saying_so(tmp_path: Path) -> None:
    out = tmp_path / "retrain.json"
    began = time.monotonic()
    with pytest.raises(RuntimeError, match=r"hung before its first step: .* in 2 s .*CAMA_RETRAIN_STALL_S"):
        _run_child(Quiet(), (), out, target=hung_child, stall_s=2.0)  # type: ignore[arg-type]
    assert (tmp_path / "child_started").is_file()
    assert time.monotonic() - began < 100  # stopped, not left to sleep its 120 s
    assert not out.exists()


def test_a_busy_child_is_not_taken_for_hung(tmp_path: Path) -> None:
    out = tmp_path / "retrain.json"
    payload = _run_child(Quiet(), (), out, target=busy_child, stall_s=8.0)  # type: ignore[arg-type]
    assert payload["candidate"] == "v0002" and payload["work"] > 0


def test_a_process_tree_counts_the_cpu_of_the_processes_below_it(tmp_path: Path) -> None:
    done = tmp_path / "worker_done"
    worker = (
        f"import pathlib, time\nwhile time.process_time() < 1.5: pass\npathlib.Path({str(done)!r}).touch()"
    )
    shell = subprocess.Popen(["sh", "-c", f'{sys.executable} -c "{worker}"; sleep 60'])
    try:
        deadline = time.monotonic() + 60
        while not done.exists() and time.monotonic() < deadline:
            time.sleep(0.1)
        assert done.exists(), "the worker did not finish its 1.5 s of CPU within 60 s"
        time.sleep(1.0)  # the worker has ended and the shell has reaped it
        cpu_s = tree_cpu_seconds(shell.pid)
        # the worker's 1.5 s, still counted once reaped (/proc counts in clock ticks: a little slack); the shell
        # itself only waits
        assert cpu_s is not None and 1.3 <= cpu_s < 2.0
    finally:
        shell.kill()
        shell.wait()
    assert tree_cpu_seconds(2**22 + 1) is None  # above Linux's largest process id: no such process
