"""Progress of a command's stages on stderr, on a terminal and in a log alike.

On a terminal a rich spinner shows the running stage with its elapsed time, and each
finished stage leaves a ``✓ stage (12.3 s)`` line.  When stderr is not a terminal (a log
file, a pipe, CI) nothing is animated: every stage prints one plain line as it starts,
``[  31.2 s] robustness, scenario 1 (1 of 3): ...``, with the seconds since the command
began, and is flushed at once, so a log shows which stage is running while it runs.
"""

from __future__ import annotations

import time
from types import TracebackType
from typing import Any

import typer

__all__ = ["StageProgress"]


class StageProgress:
    """Report the stages of a long command (a context manager).

    Parameters
    ----------
    console
        A rich ``Console`` on stderr; its ``is_terminal`` chooses between the spinner and
        plain lines.

    Examples
    --------
    >>> with StageProgress(console) as progress:  # doctest: +SKIP
    ...     reproduce(out, on_stage=progress.stage)
    ...     progress.done()
    """

    def __init__(self, console: Any) -> None:
        self.console = console
        self.terminal = bool(console.is_terminal)
        self._t0 = time.perf_counter()
        self._current: tuple[str, float] | None = None
        self._progress: Any = None
        self._task: Any = None

    def __enter__(self) -> StageProgress:
        self._t0 = time.perf_counter()
        if self.terminal:
            from rich.progress import Progress, SpinnerColumn, TextColumn, TimeElapsedColumn

            self._progress = Progress(
                SpinnerColumn(),
                TextColumn("{task.description}"),
                TimeElapsedColumn(),
                console=self.console,
                transient=False,
            )
            self._progress.__enter__()
            self._task = self._progress.add_task("starting", total=None)
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if self._progress is not None:
            self._progress.remove_task(self._task)
            self._progress.__exit__(exc_type, exc, tb)
            self._progress = None

    def elapsed(self) -> float:
        """Seconds since the command began (entering the context)."""
        return time.perf_counter() - self._t0

    def stage(self, msg: str) -> None:
        """A new stage starts (the previous one, if any, has finished)."""
        now = time.perf_counter()
        if self.terminal:
            if self._current is not None:
                done, since = self._current
                self._progress.console.print(f"  [green]✓[/green] {done} ({now - since:.1f} s)")
            self._progress.update(self._task, description=msg)
        else:
            typer.echo(f"[{now - self._t0:7.1f} s] {msg}", err=True)
        self._current = (msg, now)

    def done(self) -> None:
        """The last stage has finished (prints its line, or ``[ ... s] done``)."""
        self.stage("done")
        self._current = None
