"""CPU time of a process and of every process below it, read from Linux's `/proc`: how a job tells a child that
works from one that hangs.

A retraining child is CPU-bound from start to end (loading rasters, training, the gate's evaluations), but none of
its phases is sure to report progress often: evaluating a model on the validation sites says nothing for minutes.
A deadlocked child (every thread waiting on a lock, as one was seen in CPython's multiprocessing resource tracker)
uses no CPU at all. So the CPU time of the child and its descendants (data loader workers, the resource tracker) is
the signal: it grows while anything works and stands still when all of it waits.
"""

import os
from pathlib import Path

PROC = Path("/proc")
_TICKS_PER_S = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100


def _stat_fields(pid: int) -> list[str] | None:
    """The fields of `/proc/PID/stat` after the command name (state first), or None (no such process)."""
    try:
        text = (PROC / str(pid) / "stat").read_text(encoding="ascii", errors="replace")
    except OSError:
        return None
    # the command name is in parentheses and may itself hold spaces and parentheses
    return text[text.rfind(")") + 2 :].split()


def _cpu_s(fields: list[str]) -> float:
    """User plus system CPU seconds of one process's threads and of the children it has reaped."""
    return sum(int(value) for value in fields[11:15]) / _TICKS_PER_S


def _children_by_parent() -> dict[int, list[int]]:
    """Every live process id, listed under its parent's."""
    children: dict[int, list[int]] = {}
    for entry in PROC.iterdir():
        if not entry.name.isdigit():
            continue
        fields = _stat_fields(int(entry.name))
        if fields is not None:
            children.setdefault(int(fields[1]), []).append(int(entry.name))
    return children


def tree_cpu_seconds(pid: int) -> float | None:
    """CPU seconds used so far by `pid` and every live process below it (each with the children it has reaped);
    None when the process is gone or the system has no `/proc` (the caller then cannot tell a hang)."""
    root = _stat_fields(pid)
    if root is None:
        return None
    total, below = _cpu_s(root), _children_by_parent()
    pending = list(below.get(pid, []))
    while pending:
        child = pending.pop()
        fields = _stat_fields(child)
        if fields is None:
            continue
        total += _cpu_s(fields)
        pending.extend(below.get(child, []))
    return total
