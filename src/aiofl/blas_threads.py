"""One BLAS thread for aiofl's small dense linear algebra.

aiofl's matrices are small (a closed loop has ≤ 30 states): a multi-threaded BLAS gains
nothing on them and loses much when the cores are busy.  OpenBLAS's worker threads wait
for each other at every call; with the cores taken by the engine's numba threads, the
orbit-analysis workers (:mod:`aiofl.reporting.orbit_pool`) or another job, the report's
``scipy.linalg.expm`` of ≤ 9 × 9 matrices averaged 7.6 ms per call instead of ~10 µs on the
2-core development machine, and the report's linearisations, matrix exponentials and
implicit integrations all call BLAS or LAPACK (``benchmarks/bench_blas_threads.py``
measures it).  One thread computes the same numbers.

:func:`one_blas_thread` limits the BLAS libraries loaded in this process to one thread, by
:mod:`threadpoolctl` (which knows OpenBLAS, MKL and BLIS); the ``aiofl`` command, the
orbit workers and :func:`aiofl.reporting.reproduce.reproduce` use it.  A program that
imports aiofl as a library keeps its own settings otherwise.
"""

from __future__ import annotations

from typing import Any

__all__ = ["one_blas_thread"]


def one_blas_thread() -> Any:
    """Limit BLAS to one thread in this process: the returned
    :class:`threadpoolctl.threadpool_limits` is also a context manager that restores the
    previous limits on exit (called bare, the limit stays for the process).

    threadpoolctl limits the libraries loaded when it is called, so numpy's and scipy's
    BLAS (each wheel ships its own OpenBLAS) are loaded first: a limit set before
    ``scipy.linalg`` was imported left scipy's at two threads."""
    import numpy.linalg  # noqa: F401 - loads numpy's BLAS
    import scipy.linalg  # noqa: F401 - loads scipy's BLAS
    from threadpoolctl import threadpool_limits

    return threadpool_limits(limits=1, user_api="blas")
