"""Where per-clip reconstructions run: a local process pool (default) or a Ray cluster, behind one protocol.

Both run the same module-level task function on picklable tasks and give the results back in task order,
so a site reconstructs identically on either. Each task runs in its own process (pycolmap holds the GIL for
long stretches and keeps global state; separate processes keep clips independent).
"""

import logging
import multiprocessing
from collections.abc import Callable, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from typing import Any, Literal, Protocol, TypeVar

logger = logging.getLogger(__name__)

ExecutorName = Literal["local", "ray"]
EXECUTORS: tuple[str, ...] = ("local", "ray")
T = TypeVar("T")
R = TypeVar("R")
DoneCallback = Callable[[int], None]
"""Called with a task's index when it finishes (for progress bars)."""


class Executor(Protocol):
    """Runs `fn` over tasks in separate processes; results in task order, `on_done(index)` as each ends."""

    name: str
    workers: int

    def map(
        self, fn: Callable[[T], R], tasks: Sequence[T], *, on_done: DoneCallback | None = None
    ) -> list[R]: ...


def _log_like_parent(level: int) -> None:
    """Worker start-up: log at the parent's level, so each clip's per-iteration lines are seen."""
    logging.basicConfig(level=level, format="%(levelname)s %(processName)s %(name)s: %(message)s")


class _WorkerCount:
    """The validated number of tasks an executor runs at once."""

    def __init__(self, workers: int = 2) -> None:
        if workers < 1:
            raise ValueError(f"{type(self).__name__}: workers must be >= 1, got {workers}")
        self.workers = workers


class LocalExecutor(_WorkerCount):
    """A process pool on this machine (spawned processes: safe beside threads such as progress bars)."""

    name = "local"

    def map(
        self, fn: Callable[[T], R], tasks: Sequence[T], *, on_done: DoneCallback | None = None
    ) -> list[R]:
        """Run every task; an exception in a task is raised here after cancelling the rest."""
        if not tasks:
            return []
        context = multiprocessing.get_context("spawn")
        results: dict[int, R] = {}
        level = logging.getLogger().getEffectiveLevel()
        with ProcessPoolExecutor(
            min(self.workers, len(tasks)), mp_context=context, initializer=_log_like_parent, initargs=(level,)
        ) as pool:
            pending = {pool.submit(fn, task): i for i, task in enumerate(tasks)}
            while pending:
                finished, _ = wait(pending, return_when=FIRST_COMPLETED)
                for future in finished:
                    index = pending.pop(future)
                    results[index] = future.result()
                    if on_done is not None:
                        on_done(index)
        return [results[i] for i in range(len(tasks))]


class RayExecutor(_WorkerCount):
    """Ray tasks: a local Ray instance of `workers` CPUs unless Ray is already initialised (e.g. a cluster
    joined by `ray.init(address=...)` before the call); one CPU per task."""

    name = "ray"

    def map(
        self, fn: Callable[[T], R], tasks: Sequence[T], *, on_done: DoneCallback | None = None
    ) -> list[R]:
        """Run every task on Ray; a local instance started here is shut down afterwards."""
        import ray

        if not tasks:
            return []
        started = not ray.is_initialized()
        if started:
            ray.init(
                num_cpus=self.workers,
                include_dashboard=False,
                log_to_driver=False,
                logging_level=logging.WARNING,
            )
        try:
            remote = ray.remote(num_cpus=1, max_retries=0)(fn)
            refs: dict[Any, int] = {remote.remote(task): i for i, task in enumerate(tasks)}
            results: dict[int, R] = {}
            waiting = list(refs)
            while waiting:
                ready, waiting = ray.wait(waiting, num_returns=1)
                index = refs[ready[0]]
                results[index] = ray.get(ready[0])
                if on_done is not None:
                    on_done(index)
            return [results[i] for i in range(len(tasks))]
        finally:
            if started:
                ray.shutdown()


def make_executor(name: str, workers: int = 2) -> Executor:
    """The executor called `name` ("local" or "ray") with `workers` parallel tasks."""
    if name == "local":
        return LocalExecutor(workers)
    if name == "ray":
        return RayExecutor(workers)
    raise ValueError(f"executor must be one of {EXECUTORS}, got {name!r}")
