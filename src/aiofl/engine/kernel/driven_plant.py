r"""The template of the driven simulation: a plant driven by a sampled input, RK4 per sample,
one member per parameter vector (see :mod:`aiofl.engine.driven` for the equations, the
members that stop and the outputs).

:func:`_tpl_driven` is plain Python until the compile factory compiles it with one plant's
functions bound under the placeholder names below
(:func:`aiofl.engine.build.driven_kernel.driven_kernel`).
"""

from __future__ import annotations

import numpy as np

__all__: list[str] = []  # a template, compiled per plant (aiofl.engine.build.driven_kernel)

# Placeholders: stand-ins so this module imports.  The compiled template gets them from
# aiofl/engine/build/driven_kernel.py:driven_kernel (its ``space``):
_F = _G = _H = None  # the plant's f, g, h: scalar private copies (bindings.plant_function)
_N = 1  # the plant's number of states
_PRANGE = range  # numba.prange: members in parallel
PLACEHOLDERS = tuple(
    """
    _F _G _H _N _PRANGE
    """.split()  # noqa: SIM905 - the names as a reader scans them
)
"""The names of the placeholder block: what the compile factory checks a recipe binds
when a template of this module reads one (:func:`aiofl.engine.build.compile.build`)."""


def _tpl_driven(
    u, ts, params, x0, delay, substeps, limit, gain, y_meas, y_out, stopped
):  # pragma: no cover - compiled
    """Simulate every member (row of ``params``) over the log; see the module notes."""
    n_members = params.shape[0]
    n_samples = u.shape[0]
    h = ts / substeps
    inject = False
    for i in range(_N):
        if gain[i] != 0.0:
            inject = True
    for m in _PRANGE(n_members):
        p = params[m].copy()
        x = x0[m].copy()
        xs = np.empty(_N)
        k1 = np.empty(_N)
        k2 = np.empty(_N)
        k3 = np.empty(_N)
        k4 = np.empty(_N)
        stopped[m] = -1
        y_out[m, 0] = _H(x, p)
        for k in range(n_samples - 1):
            j = k - delay
            uk = u[j] if j >= 0 else 0.0
            yk = y_meas[k]
            for _s in range(substeps):
                for stage in range(4):
                    if stage == 0:
                        for i in range(_N):
                            xs[i] = x[i]
                    elif stage == 1:
                        for i in range(_N):
                            xs[i] = x[i] + 0.5 * h * k1[i]
                    elif stage == 2:
                        for i in range(_N):
                            xs[i] = x[i] + 0.5 * h * k2[i]
                    else:
                        for i in range(_N):
                            xs[i] = x[i] + h * k3[i]
                    fx = _F(xs, p)
                    gx = _G(xs, p)
                    e = 0.0
                    if inject:
                        e = yk - _H(xs, p)
                    kk = k1 if stage == 0 else (k2 if stage == 1 else (k3 if stage == 2 else k4))
                    for i in range(_N):
                        kk[i] = fx[i] + gx[i] * uk + gain[i] * e
                for i in range(_N):
                    x[i] = x[i] + h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])
            ok = True
            for i in range(_N):
                if not (abs(x[i]) <= limit):  # NaN fails too
                    ok = False
            yn = _H(x, p)
            if not (ok and np.isfinite(yn)):
                stopped[m] = k + 1
                for q in range(k + 1, n_samples):
                    y_out[m, q] = np.nan
                break
            y_out[m, k + 1] = yn
    return 0
