"""The report's orbit verdicts in worker processes equal the sequential ones."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from aiofl.config import load_config
from aiofl.reporting.orbit_pool import case_verdicts, closed_loop_verdict, orbit_verdicts

# two designs whose equilibrium is unstable (so the tracking orbit is analysed) and whose
# analysis is among the cheapest (~1.5 s each)
PRESETS = ("frontier-s3-inleso", "retuned-s2-inleso")


def _same(a, b, path=""):
    """Equal records, the wall time ("seconds") aside."""
    if isinstance(a, dict):
        assert set(a) == set(b), path
        for k in a:
            if k != "seconds":
                _same(a[k], b[k], f"{path}.{k}")
    elif isinstance(a, (list, tuple, np.ndarray)):
        assert len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            _same(x, y, f"{path}[{i}]")
    else:
        assert a == b, (path, a, b)


@pytest.mark.slow  # worker processes start and import aiofl (~5 s each time)
def test_orbit_verdicts_in_two_workers_equal_the_sequential_loop():
    jobs = {p: closed_loop_verdict(load_config(p), orbit=False) for p in PRESETS}
    assert all(v["verdict"] == "unstable" for v in jobs.values())
    alone = orbit_verdicts(jobs, workers=1)
    pooled = orbit_verdicts(jobs, workers=2)
    assert list(pooled) == list(PRESETS)
    for p in PRESETS:
        assert pooled[p]["floquet"] is not None, pooled[p]
        _same(alone[p], pooled[p], p)
    # the whole verdict (linearisation and orbit) computed in the workers, started in the
    # order given, equals the two computed here
    whole = case_verdicts(PRESETS[::-1], workers=2)
    assert list(whole) == list(PRESETS[::-1])
    for p in PRESETS:
        _same({**jobs[p], "orbit": alone[p]}, whole[p], p)


def test_one_blas_thread_limits_numpy_and_scipy_in_a_fresh_process() -> None:
    """In a process that has imported neither numpy nor scipy (the aiofl command, an orbit
    worker), ``one_blas_thread`` still limits both BLAS libraries, numpy's and scipy's, to
    one thread (threadpoolctl limits only what is loaded: called first, it left scipy's at
    its default)."""
    code = (
        "import json, sys\n"
        "from aiofl.blas_threads import one_blas_thread\n"
        "assert 'scipy' not in sys.modules\n"
        "one_blas_thread()\n"
        "import scipy.linalg\n"
        "from threadpoolctl import threadpool_info\n"
        "print(json.dumps([i['num_threads'] for i in threadpool_info() "
        "if i['user_api'] == 'blas']))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    threads = json.loads(out.stdout.strip().splitlines()[-1])
    assert len(threads) >= 2 and set(threads) == {1}
