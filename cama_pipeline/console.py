"""The `cama` commands' console and exit codes: every command prints through `console` and leaves through
`bad_input` or `failure`, so what it prints does not depend on the terminal and how it exits follows one policy.

Exit codes:

- 0 (`EXIT_OK`): success, including "up to date, nothing done".
- 1 (`EXIT_FAILURE`): a failure while working: a stage that broke mid-run (every SfM clip failed), a server that
  cannot bind its port, an unexpected exception (Python's own exit code for a traceback).
- 2 (`EXIT_BAD_INPUT`): bad input or options: a missing or unreadable file, a data set or workspace that breaks
  its layout, an option value that a config rejects. click's own usage errors (unknown option, missing argument,
  a value out of an option's range) exit 2 too.

Errors go to stderr as one line `error: <message>`; the message names the file, field or option at fault.

Output that is not a terminal (a pipe, a log file, `typer.testing.CliRunner`) is never hard-wrapped: rich would
otherwise wrap lines at COLUMNS or at the width of whichever terminal the process has on another stream, which
broke assertions on messages with long paths. Tables are then laid out `PIPE_WIDTH` columns wide; keep paths out
of tables (print them on their own line) so that a long path does not crush the table.
"""

from rich.console import Console, ConsoleDimensions
from rich.markup import escape
from typer import Exit

EXIT_OK = 0
EXIT_FAILURE = 1
EXIT_BAD_INPUT = 2

INPUT_ERRORS: tuple[type[Exception], ...] = (ValueError, FileNotFoundError)
"""Errors that mean bad input (exit 2): a missing file, or a ValueError naming the file, field or option at fault.
The project's input errors subclass ValueError: DatasetError, WorkspaceError, CheckpointError, ViewInputError, ..."""

PIPE_WIDTH = 200
"""Columns of output that is not a terminal: room for the widest table (`cama eval`'s), whatever COLUMNS says."""
PIPE_HEIGHT = 25


class CliConsole(Console):
    """A rich console that decides at each print where its output goes (tests swap sys.stdout after import):
    a terminal keeps rich's layout at the terminal's width; anything else gets soft wrap (a line is printed whole)
    and a fixed `PIPE_WIDTH` for tables and rules."""

    @property
    def size(self) -> ConsoleDimensions:
        """The terminal's size; `PIPE_WIDTH` x `PIPE_HEIGHT` when output is not a terminal."""
        if self.is_terminal:
            return super().size
        return ConsoleDimensions(PIPE_WIDTH, PIPE_HEIGHT)

    @size.setter
    def size(self, new_size: tuple[int, int]) -> None:
        self._width, self._height = new_size

    @property
    def soft_wrap(self) -> bool:
        """Print each line whole (the reader's terminal wraps it) unless rich can lay it out on a terminal."""
        return self._soft_wrap or not self.is_terminal

    @soft_wrap.setter
    def soft_wrap(self, value: bool) -> None:
        self._soft_wrap = value


console = CliConsole()
"""Standard output of every `cama` command."""
error_console = CliConsole(stderr=True)
"""Standard error: the `error: ...` lines."""


def bad_input(err: Exception | str) -> Exit:
    """Print `error: <err>` on stderr and return the exit to raise for bad input or options (code 2)."""
    return _exit(err, EXIT_BAD_INPUT)


def failure(err: Exception | str) -> Exit:
    """Print `error: <err>` on stderr and return the exit to raise for a failure while working (code 1)."""
    return _exit(err, EXIT_FAILURE)


def _exit(err: Exception | str, code: int) -> Exit:
    error_console.print(f"[red]error:[/red] {escape(str(err))}", highlight=False)
    return Exit(code=code)
