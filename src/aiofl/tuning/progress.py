"""The progress bar of :func:`aiofl.tuning.search.tune` (rich, on stderr).

It prints the numbers ``aiofl tune``'s summary prints at the end
(:func:`aiofl.cli.tune_command.summary_text`), so the two never disagree.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:  # pragma: no cover
    from aiofl.tuning.space import TuneSettings

__all__ = ["TuneProgress"]


class TuneProgress:
    """A rich progress bar on stderr: generation, best objective, evaluations per second.

    The numbers are the ones the summary prints at the end: the best objective so far
    (with NSGA-II, which has no single best, the lowest first objective of a feasible
    design, labelled with its name: the front's end), and the evaluations per second of
    the whole run so far (:attr:`aiofl.tuning.search.TuneResult.evals_per_second`:
    simulated candidates over the time spent simulating them, the first generation's
    compile included), not of the last generation alone.  ``fields`` holds what was last
    shown.
    """

    def __init__(
        self, st: TuneSettings, ev: Any, *, enabled: bool, first_objective: str | None = None
    ) -> None:
        """The progress bar of a tuning run.

        Parameters
        ----------
        st
            The run's settings (algorithm, population, generations).
        ev
            The evaluator (its ``description`` says whether it runs on Dask).
        enabled
            Show the bar (False: every method does nothing).
        first_objective
            The first objective's name, labelled ``lowest NAME`` (None: ``best``).
        """
        self.enabled = enabled
        self.total = st.generations
        where = getattr(ev, "description", "")
        self.desc = f"{st.algorithm.upper()} {st.population}x{st.generations}" + (
            " dask" if where.startswith("dask") else ""
        )
        self.label = "best" if first_objective is None else f"lowest {first_objective}"
        self.fields: dict[str, str] = {"label": self.label, "best": "—", "rate": "—"}
        self._p: Any = None
        self._task: Any = None

    def __enter__(self) -> TuneProgress:
        if self.enabled:
            from rich.console import Console
            from rich.progress import (
                BarColumn,
                MofNCompleteColumn,
                Progress,
                TextColumn,
                TimeElapsedColumn,
                TimeRemainingColumn,
            )

            self._p = Progress(
                TextColumn("[bold]{task.description}", markup=True),
                BarColumn(),
                MofNCompleteColumn(),
                TextColumn(
                    "gen · {task.fields[label]} {task.fields[best]} · {task.fields[rate]} eval/s",
                    markup=False,
                ),
                TimeElapsedColumn(),
                TimeRemainingColumn(),
                console=Console(stderr=True),
            )
            self._p.__enter__()
            self._task = self._p.add_task(self.desc, total=self.total, **self.fields)
        return self

    def update(self, gen: int, best: float, live_n: int, live_s: float) -> None:
        """Show generation ``gen`` done, ``best`` so far, and ``live_n`` candidates simulated
        in ``live_s`` seconds over the run so far (none: every generation was replayed).

        Parameters
        ----------
        gen
            The generations done.
        best
            The best objective so far.
        live_n, live_s
            Candidates simulated, and the seconds they took, over the run so far.
        """
        self.fields = {
            "label": self.label,
            "best": f"{best:.6g}" if np.isfinite(best) else "—",
            "rate": f"{live_n / live_s:.1f}" if live_n and live_s > 0 else "replayed",
        }
        if self._p is not None:
            self._p.update(self._task, completed=gen, **self.fields)

    def __exit__(self, *exc: Any) -> None:
        if self._p is not None:
            self._p.__exit__(*exc)
