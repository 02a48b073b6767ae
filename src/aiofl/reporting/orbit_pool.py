"""The report's closed-loop verdicts, reconciled with the orbit analysis, on every core.

:func:`closed_loop_verdict` is a report case's verdict: the linearisation
(:func:`aiofl.analysis.linearize.closed_loop_verdict`) and the reconciled orbit verdict
(:func:`orbit_verdict`: :func:`aiofl.analysis.orbit.orbit_analysis` integrates the
variational equation of the closed loop with scipy's BDF and a complex-step Jacobian: pure
Python on one core, up to tens of seconds for an INLESO design, and independent from design
to design).  :func:`case_verdicts` (both) and :func:`orbit_verdicts` (the orbit verdict of
a given linearisation) hand them to worker processes (one per core, at most
:data:`MAX_WORKERS`), each a fresh ``python -m aiofl.reporting.orbit_pool`` (not a fork of
a process whose numba threads run, and not a re-import of the caller's ``__main__``, so a
script without a ``__main__`` guard may call it).  A worker reads jobs (a preset's name,
the report's sample time and the linearisation verdict, or None to compute it) as
length-prefixed pickles on its stdin, loads the config itself and writes each record back
on stdout; the parent gives the next job to whichever worker is free, in the order given.
The same function on the same inputs: the records equal those of the sequential loop
(``workers=1``, also used for a single design or core).
"""

from __future__ import annotations

import os
import pickle
import queue
import struct
import subprocess
import sys
import threading
from collections.abc import Mapping, Sequence
from typing import IO, Any

__all__ = ["MAX_WORKERS", "case_verdicts", "closed_loop_verdict", "orbit_verdict", "orbit_verdicts"]

MAX_WORKERS = 4
"""At most this many worker processes (each holds a Python interpreter with aiofl)."""


def orbit_verdict(cfg: Any, verdict: dict[str, Any]) -> dict[str, Any]:
    """The reconciled verdict of a report's case (:func:`aiofl.analysis.orbit.orbit_analysis`,
    its quick settings); a failure is reported in it, not raised."""
    from aiofl.analysis.orbit import orbit_analysis

    try:
        return orbit_analysis(cfg, verdict, unit=cfg.plant.output_unit, quick=True)
    except Exception as exc:  # the report must not fail because one analysis did
        return {"verdict": f"orbit analysis failed: {type(exc).__name__}: {exc}", "short": "—"}


def closed_loop_verdict(cfg: Any, *, orbit: bool = True) -> dict[str, Any]:
    """Closed-loop linearisation verdict of a report case, with its reconciled verdict.

    Uses :func:`aiofl.analysis.linearize.closed_loop_verdict` (``{"verdict": str,
    "eigenvalues": [[re, im], ...]}``) and adds ``"orbit"`` (:func:`orbit_verdict`:
    equilibrium, limit cycle, tracking orbit).  A failure of the analysis is reported in the
    verdict, not raised.  ``orbit = False`` (the report, for a run that diverged: the
    simulation and an unstable linearisation agree, nothing to reconcile) leaves the orbit
    out.
    """
    from aiofl.analysis.linearize import closed_loop_verdict as linearized_verdict

    try:
        out = dict(linearized_verdict(cfg))
    except Exception as exc:  # the report must not fail because one analysis did
        out = {"verdict": f"analysis failed: {type(exc).__name__}: {exc}", "eigenvalues": []}
    if orbit:
        out["orbit"] = orbit_verdict(cfg, out)
    return out


def _verdict(preset: str, ts: float | None, verdict: dict[str, Any] | None) -> dict[str, Any]:
    """A worker's job, the config loaded by name: :func:`orbit_verdict` of the given
    linearisation verdict, or (None) the whole :func:`closed_loop_verdict`."""
    from aiofl.config import load_config

    cfg = load_config(preset)
    if ts is not None:
        cfg = cfg.with_sample_time(ts)
    return closed_loop_verdict(cfg) if verdict is None else orbit_verdict(cfg, verdict)


def _send(stream: IO[bytes], obj: Any) -> None:
    data = pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)
    stream.write(struct.pack("<Q", len(data)) + data)
    stream.flush()


def _receive(stream: IO[bytes]) -> Any:
    head = stream.read(8)
    if len(head) < 8:
        raise EOFError("the orbit worker closed its output")
    (size,) = struct.unpack("<Q", head)
    return pickle.loads(stream.read(size))  # our own worker's records


Job = tuple[str, float | None, dict[str, Any] | None]
"""A worker's job: preset name, sample time, linearisation verdict (None: computed too)."""


def _serve(jobs: queue.Queue[Job], out: dict[str, Any]) -> None:
    """Run one worker process and feed it jobs until the queue is empty."""
    cmd = [sys.executable, "-m", "aiofl.reporting.orbit_pool"]
    with subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE) as proc:
        assert proc.stdin is not None and proc.stdout is not None
        try:
            while True:
                try:
                    job = jobs.get_nowait()
                except queue.Empty:
                    break
                _send(proc.stdin, job)
                out[job[0]] = _receive(proc.stdout)
        except (EOFError, OSError):
            pass  # a dead worker: its unfinished job is done by orbit_verdicts itself
        finally:
            proc.stdin.close()


def orbit_verdicts(
    jobs: Mapping[str, dict[str, Any]], ts: float | None = None, workers: int | None = None
) -> dict[str, dict[str, Any]]:
    """The orbit verdict of each preset in ``jobs`` (name → its linearisation verdict).

    Parameters
    ----------
    jobs
        Preset name → :func:`aiofl.analysis.linearize.closed_loop_verdict` record.
    ts
        The report's sample time (``aiofl reproduce --ts``), applied to each config.
    workers
        Worker processes (default: the usable cores, at most :data:`MAX_WORKERS`); 1 runs
        them in this process, one after the other.

    Returns
    -------
    dict
        Preset name → the record of :func:`aiofl.analysis.orbit.orbit_analysis`, in the
        order of ``jobs``.  A design whose worker died is analysed here instead.
    """
    return _pool([(name, ts, v) for name, v in jobs.items()], workers)


def case_verdicts(
    presets: Sequence[str], ts: float | None = None, workers: int | None = None
) -> dict[str, dict[str, Any]]:
    """:func:`closed_loop_verdict` (linearisation and orbit) of each preset, started in the
    order given (the report starts the likely slowest first), on ``workers`` processes as
    :func:`orbit_verdicts`; preset name → record, in the order of ``presets``.

    Parameters
    ----------
    presets
        The preset names.
    ts
        Sample every design at this sample time [s] (None: as configured).
    workers
        The processes (None: the usable cores, at most :data:`MAX_WORKERS`).

    Returns
    -------
    dict of str to dict
    """
    return _pool([(name, ts, None) for name in presets], workers)


def _pool(jobs: list[Job], workers: int | None) -> dict[str, dict[str, Any]]:
    if workers is None:  # the cores this process may use (sched_getaffinity: Linux only)
        usable = os.sched_getaffinity(0) if hasattr(os, "sched_getaffinity") else None
        workers = min(len(usable) if usable else (os.cpu_count() or 1), MAX_WORKERS)
    n = max(1, min(workers, len(jobs)))
    if n == 1:
        return {name: _verdict(name, ts, v) for name, ts, v in jobs}
    todo: queue.Queue[Job] = queue.Queue()
    for job in jobs:
        todo.put(job)
    done: dict[str, Any] = {}
    threads = [threading.Thread(target=_serve, args=(todo, done)) for _ in range(n)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    return {name: done[name] if name in done else _verdict(name, ts, v) for name, ts, v in jobs}


def _worker() -> None:
    """The worker's loop: a job from stdin, its record to stdout, until stdin closes
    (BLAS limited to one thread: :mod:`aiofl.blas_threads`)."""
    from aiofl.blas_threads import one_blas_thread

    one_blas_thread()
    stdin, stdout = sys.stdin.buffer, sys.stdout.buffer
    sys.stdout = sys.stderr  # nothing else may write into the record stream
    while True:
        try:
            preset, ts, verdict = _receive(stdin)
        except EOFError:
            return
        _send(stdout, _verdict(preset, ts, verdict))


if __name__ == "__main__":
    _worker()
