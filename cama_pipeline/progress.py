"""Progress of a long stage: a rich bar on a terminal, otherwise a plain logged line every few seconds.

Without a terminal (output piped, in a log file, under `make`) rich draws nothing until the end, so long work
looked silent. Here the same `add_task` / `advance` / `update` calls then log, through the stage's logger,
at most one line per task every `interval_s` (env `CAMA_PROGRESS_INTERVAL_S`, default 5 s), plus one when a
task reaches its total (or the block ends before), e.g.
`synthetic: render images 812/2406 (34 %), 9.1/s, about 2 min 55 s left`.

A caller that shows progress elsewhere (the editor's job runner) wraps the stage in `observed_progress`: every
step of every bar made inside the block then also reaches its observer, bar shown or not, and an observer that
raises stops the stage at that step.
"""

import logging
import os
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass
from types import TracebackType

import rich
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TaskID, TextColumn, TimeRemainingColumn

INTERVAL_ENV = "CAMA_PROGRESS_INTERVAL_S"
DEFAULT_INTERVAL_S = 5.0

logger = logging.getLogger(__name__)

ProgressObserver = Callable[[str, float, float | None], None]
"""Called with a bar's text (`label: description`), its completed count and its total (None: unknown)."""
_OBSERVER: ContextVar[ProgressObserver | None] = ContextVar("cama_progress_observer", default=None)


@contextmanager
def observed_progress(observer: ProgressObserver) -> Iterator[None]:
    """Within the block (in this thread and context), every `StageProgress` created also calls `observer` on
    each step; an exception the observer raises stops the stage where it stepped (how a job is cancelled)."""
    token = _OBSERVER.set(observer)
    try:
        yield
    finally:
        _OBSERVER.reset(token)


def output_is_terminal() -> bool:
    """Whether rich can draw a live bar on its console (a terminal that is not dumb, or Jupyter)."""
    console = rich.get_console()
    return console.is_jupyter or (console.is_terminal and not console.is_dumb_terminal)


def interval_from_env() -> float:
    """Seconds between two logged lines of one task: `CAMA_PROGRESS_INTERVAL_S`, else 5."""
    raw = os.environ.get(INTERVAL_ENV, "").strip()
    if not raw:
        return DEFAULT_INTERVAL_S
    try:
        seconds = float(raw)
    except ValueError:
        raise ValueError(f"{INTERVAL_ENV}={raw!r} is not a number of seconds") from None
    if not seconds >= 0:  # NaN too
        raise ValueError(f"{INTERVAL_ENV}={raw!r} must be zero or more seconds")
    return seconds


def format_duration(seconds: float) -> str:
    """`12 s`, `2 min 55 s`, `1 h 4 min`."""
    whole = max(0, round(seconds))
    if whole < 60:
        return f"{whole} s"
    if whole < 3600:
        return f"{whole // 60} min {whole % 60} s"
    return f"{whole // 3600} h {whole % 3600 // 60} min"


@dataclass
class _Task:
    description: str
    total: float | None
    started: float
    completed: float = 0.0
    last_line: float = 0.0
    first: tuple[float, float] | None = None  # (time, completed) at its first step, where the rate starts
    finished: bool = False  # its line at the total is written
    logged: tuple[float, float | None, str] | None = None  # (completed, total, description) last written


class StageProgress:
    """Progress bars of one stage, as a context manager; `enabled=False` shows and logs nothing.

    `terminal` (default: detected on entry) picks the rich bar or logged lines; `clock` and `interval_s`
    (default: from the environment) pace the lines.
    """

    def __init__(
        self,
        label: str,
        *,
        logger: logging.Logger = logger,
        enabled: bool = True,
        transient: bool = False,
        terminal: bool | None = None,
        interval_s: float | None = None,
        clock: Callable[[], float] = time.monotonic,
    ):
        self.label = label
        self.logger = logger
        self.enabled = enabled
        self.transient = transient
        self.terminal = terminal
        self.interval_s = interval_from_env() if interval_s is None else interval_s
        self.clock = clock
        self._bar: Progress | None = None
        self._bar_ids: dict[int, TaskID] = {}
        self._observer = _OBSERVER.get()
        self._tasks: dict[int, _Task] = {}
        self._lock = threading.Lock()

    def __enter__(self) -> "StageProgress":
        terminal = output_is_terminal() if self.terminal is None else self.terminal
        if self.enabled and terminal:
            columns = (
                TextColumn("{task.description}"),
                BarColumn(),
                MofNCompleteColumn(),
                TimeRemainingColumn(elapsed_when_finished=True),
            )
            self._bar = Progress(*columns, transient=self.transient).__enter__()
        return self

    def __exit__(
        self, kind: type[BaseException] | None, error: BaseException | None, trace: TracebackType | None
    ) -> None:
        if self._bar is not None:
            self._bar.__exit__(kind, error, trace)
            return
        if kind is None and self.enabled:
            with self._lock:
                for task in self._tasks.values():
                    if task.completed > 0 and task.logged != _state(task):
                        self._write(task)

    def add_task(self, description: str = "", total: float | None = None) -> int:
        """A new bar; its id for `advance` and `update`."""
        with self._lock:
            task_id = len(self._tasks)
            now = self.clock()
            self._tasks[task_id] = _Task(description, total, started=now, last_line=now)
            if self._bar is not None:
                self._bar_ids[task_id] = self._bar.add_task(self._text(description), total=total)
        return task_id

    def advance(self, task_id: int, amount: float = 1) -> None:
        self.update(task_id, advance=amount)

    def update(
        self,
        task_id: int,
        *,
        advance: float = 0,
        completed: float | None = None,
        total: float | None = None,
        description: str | None = None,
    ) -> None:
        """Like rich's `Progress.update`: `None` leaves a field as it is."""
        if self._bar is not None:
            text = None if description is None else self._text(description)
            self._bar.update(
                self._bar_ids[task_id], advance=advance, completed=completed, total=total, description=text
            )
        with self._lock:
            task = self._tasks[task_id]
            now = self.clock()
            if total is not None and total != task.total:  # a new phase: its own rate and time left
                task.total, task.started, task.first, task.finished = total, now, None, False
            before = task.completed
            task.completed = (task.completed if completed is None else completed) + advance
            if task.first is None and task.completed != before:
                task.first = (now, task.completed)
            task.description = task.description if description is None else description
            state = _state(task)
            if self._bar is None and self.enabled:
                self._log_step(task, now)
        if self._observer is not None:
            self._observer(self._text(state[2]), state[0], state[1])

    def _log_step(self, task: _Task, now: float) -> None:
        """The task's line when it reaches its total, or when the interval has passed since its last line."""
        at_total = task.total is not None and task.completed >= task.total
        if at_total and not task.finished:
            task.finished = True
            self._write(task)
        elif now - task.last_line >= self.interval_s and task.logged != _state(task):
            self._write(task)

    def _text(self, description: str) -> str:
        return f"{self.label}: {description}" if description else self.label

    def _write(self, task: _Task) -> None:
        now = self.clock()
        task.last_line, task.logged = now, _state(task)
        self.logger.info("%s", _line(self._text(task.description), task, now))


def _state(task: _Task) -> tuple[float, float | None, str]:
    return task.completed, task.total, task.description


def _line(text: str, task: _Task, now: float) -> str:
    """`text done/total (pct %), rate, about T left` (`done in T` at the total; no total: `text done, rate`).

    The rate counts from the first step, so that a slow start (worker processes, a model loading) does not
    make the first estimates hours long; before a second step there is none.
    """
    parts = [f"{text} {task.completed:.0f}"]
    if task.total:
        parts[0] += f"/{task.total:.0f} ({100 * task.completed / task.total:.0f} %)"
    rate = 0.0
    if task.first is not None and now > task.first[0]:
        rate = (task.completed - task.first[1]) / (now - task.first[0])
    if rate > 0:
        parts.append(f"{rate:.1f}/s" if rate >= 1 else f"{60 * rate:.1f}/min")
    if task.total and task.completed >= task.total:
        parts.append(f"done in {format_duration(now - task.started)}")
    elif task.total and rate > 0:
        parts.append(f"about {format_duration((task.total - task.completed) / rate)} left")
    return ", ".join(parts)
