r"""The orbit analyses' stiff integrator, compiled: Radau IIA (order 5) over the compiled loop.

This module is the compiled part (numba, ``cache=True``); :mod:`aiofl.analysis.loop_radau`
is its Python side (the entry's signature, the slices, the solution object).

The orbit verdicts (:mod:`aiofl.analysis.orbit`) integrate the closed loop :math:`\dot z =
F(t, z)` with its exact Jacobian (observer poles near :math:`-\omega_0 \approx -2000`:
stiff).  :func:`scipy.integrate.solve_ivp` (BDF) did it in Python, calling the compiled
loop ~10⁵ times per orbit through Python; here the whole integration is one compiled call
per slice of steps: the method is scipy's Radau IIA of order 5 (``scipy/integrate/_ivp/
radau.py``: Hairer & Wanner, *Solving Ordinary Differential Equations II*, §IV.8; the
three-stage collocation solved by a simplified Newton iteration in the transformed
variables, one real and one complex LU of :math:`\mu/h\,I - J`, the embedded third-order
error estimate, the step-size predictor of Gustafsson, the cubic collocation polynomial as
dense output), written again for numba with the same constants and decisions, and the
right-hand side and Jacobian evaluated in compiled code from the loop's settings:

- the inputs at t (the reference and its derivatives, sine / step / samples, or Han's
  precomputed outputs; the step disturbance or a held value), as
  :meth:`aiofl.analysis.orbit_loop.OrbitLoop.inputs_at` gives them;
- the plant's values and Jacobians from its compiled jets
  (:func:`aiofl.analysis.plant_jets.plant_jets`) and the loop from
  :func:`aiofl.analysis.loop_kernel.loop_eval`, both passed in as first-class functions
  (numba ``FunctionType``): this module calls no other module's compiled code by name, so
  its disk cache is one for every plant and cannot go stale.

The variational equation's Φ is carried along as :mod:`aiofl.analysis.variational` does it
on the solver's steps: the exponential midpoint rule :math:`\Phi_{k+1} = \exp(h_k J(t_k +
h_k/2, z(t_k + h_k/2)))\,\Phi_k` in the scaled coordinates z / d, the midpoint state from
the step's collocation polynomial, :math:`e^{A}` by the diagonal Padé (6, 6) approximant
with scaling and squaring (:func:`aiofl.analysis.variational.expm_small`).

The integration runs in slices of :data:`SLICE` steps; between slices Python checks the
analysis' time budget (:func:`aiofl.analysis.budget.check_budget`).  A loop whose plant has
no compiled jets (or whose jets are not the complex step's) is integrated by scipy
(:func:`aiofl.analysis.variational.trajectory`), the path the tests keep as the reference.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numba import njit

__all__ = ["DONE", "RUNNING", "TOO_SMALL", "run_slice"]

S6 = 6**0.5
C = np.array([(4 - S6) / 10, (4 + S6) / 10, 1.0])
E = np.array([-13 - 7 * S6, -13 + 7 * S6, -1.0]) / 3
MU_REAL = 3 + 3 ** (2 / 3) - 3 ** (1 / 3)
MU_COMPLEX = complex(3 + 0.5 * (3 ** (1 / 3) - 3 ** (2 / 3)), -0.5 * (3 ** (5 / 6) + 3 ** (7 / 6)))
T = np.array(
    [
        [0.09443876248897524, -0.14125529502095421, 0.03002919410514742],
        [0.25021312296533332, 0.20412935229379994, -0.38294211275726192],
        [1.0, 1.0, 0.0],
    ]
)
TI = np.array(
    [
        [4.17871859155190428, 0.32768282076106237, 0.52337644549944951],
        [-4.17871859155190428, -0.32768282076106237, 0.47662355450055044],
        [0.50287263494578682, -2.57192694985560522, 0.59603920482822492],
    ]
)
P = np.array(
    [
        [13 / 3 + 7 * S6 / 3, -23 / 3 - 22 * S6 / 3, 10 / 3 + 5 * S6],
        [13 / 3 - 7 * S6 / 3, -23 / 3 + 22 * S6 / 3, 10 / 3 - 5 * S6],
        [1 / 3, -8 / 3, 10 / 3],
    ]
)
NEWTON_MAXITER = 6
MIN_FACTOR = 0.2
MAX_FACTOR = 10.0
EPS = float(np.finfo(float).eps)
_PADE = np.array([1.0, 0.5, 5.0 / 44.0, 1.0 / 66.0, 1.0 / 792.0, 1.0 / 15840.0, 1.0 / 665280.0])

# input kinds (spec_i[0]) and the positions in spec_i / spec_f
K_HOLD, K_SINE, K_STEP, K_SAMPLES, K_HAN = range(5)
(SI_KIND, SI_DCONST, SI_HASBD, SI_MODEL, SI_IOFL, SI_N, SI_OESO, SI_RHO, SI_NZ, SI_NTAB) = range(10)
(SF_ROP, SF_D, SF_DAMP, SF_DTIME, SF_AMP, SF_OMEGA, SF_PHASE, SF_OFFSET, SF_TSTEP) = range(9)

# status in the solver state st[4]
RUNNING, DONE, TOO_SMALL = 1.0, 0.0, -1.0


# ----------------------------------------------------------------- small dense algebra
@njit(cache=True)
def _lu(a: Any, piv: Any) -> None:
    """LU with partial pivoting of the square ``a``, in place (real or complex)."""
    n = a.shape[0]
    for k in range(n):
        p = k
        big = abs(a[k, k])
        for i in range(k + 1, n):
            v = abs(a[i, k])
            if v > big:
                big, p = v, i
        piv[k] = p
        if p != k:
            for j in range(n):
                tmp = a[k, j]
                a[k, j] = a[p, j]
                a[p, j] = tmp
        if a[k, k] != 0:
            for i in range(k + 1, n):
                a[i, k] = a[i, k] / a[k, k]
                lik = a[i, k]
                if lik != 0:
                    for j in range(k + 1, n):
                        a[i, j] -= lik * a[k, j]


@njit(cache=True)
def _lu_solve(a: Any, piv: Any, b: Any) -> None:
    """Solve with :func:`_lu`'s factors, ``b`` (1-D) in place."""
    n = a.shape[0]
    for k in range(n):
        p = piv[k]
        if p != k:
            tmp = b[k]
            b[k] = b[p]
            b[p] = tmp
    for i in range(n):
        s = b[i]
        for j in range(i):
            s -= a[i, j] * b[j]
        b[i] = s
    for i in range(n - 1, -1, -1):
        s = b[i]
        for j in range(i + 1, n):
            s -= a[i, j] * b[j]
        b[i] = s / a[i, i]


@njit(cache=True)
def _expm(a: Any) -> Any:
    """:math:`e^A`: diagonal Padé (6, 6) with scaling and squaring (as
    :func:`aiofl.analysis.variational.expm_small`)."""
    n = a.shape[0]
    norm = 0.0
    for j in range(n):
        s = 0.0
        for i in range(n):
            s += abs(a[i, j])
        norm = max(norm, s)
    sq = max(0, math.ceil(math.log2(norm / 0.5))) if norm > 0.5 else 0
    x = a / 2.0**sq
    ident = np.eye(n)
    x2 = x @ x
    x4 = x2 @ x2
    x6 = x4 @ x2
    c = _PADE
    even = c[0] * ident + c[2] * x2 + c[4] * x4 + c[6] * x6
    odd = x @ (c[1] * ident + c[3] * x2 + c[5] * x4)
    lhs = even - odd
    rhs = even + odd
    piv = np.empty(n, np.int64)
    _lu(lhs, piv)
    r = np.empty((n, n))
    col = np.empty(n)
    for j in range(n):
        for i in range(n):
            col[i] = rhs[i, j]
        _lu_solve(lhs, piv, col)
        for i in range(n):
            r[i, j] = col[i]
    for _ in range(sq):
        r = r @ r
    return r


@njit(cache=True)
def _rms(x: Any) -> float:
    s = 0.0
    for v in x.flat:
        s += v * v
    return math.sqrt(s / x.size)


# ------------------------------------------------------------------------- the field
@njit(cache=True)
def _inputs(t: float, spec_i: Any, spec_f: Any, tab: Any, rd: Any) -> float:
    """The reference (and derivatives, or Han's outputs) at t into ``rd``; returns τ_d(t)."""
    kind = spec_i[SI_KIND]
    rd[:] = 0.0
    if kind == K_HOLD:
        rd[0] = spec_f[SF_ROP]
    elif kind == K_SINE:
        a, w, ph = spec_f[SF_AMP], spec_f[SF_OMEGA], spec_f[SF_PHASE]
        for k in range(rd.size):
            rd[k] = a * w**k * math.sin(w * t + ph + k * math.pi / 2)
        rd[0] += spec_f[SF_OFFSET]
    elif kind == K_STEP:
        rd[0] = spec_f[SF_OFFSET] + spec_f[SF_AMP] * (1.0 if t >= spec_f[SF_TSTEP] else 0.0)
    elif kind == K_SAMPLES:
        m = spec_i[SI_NTAB]
        grid, samples = tab[0, :m], tab[1, :m]
        rd[0] = np.interp(t, grid, samples)
        if rd.size > 1:
            dt = grid[1] - grid[0] if m > 1 else 1.0
            i = int(t // dt)
            if 0 <= i < m - 1:
                rd[1] = (samples[i + 1] - samples[i]) / dt
    else:  # Han's TD: its precomputed outputs
        m = spec_i[SI_NTAB]
        rd[0] = np.interp(t, tab[0, :m], tab[1, :m])
        rd[1] = np.interp(t, tab[0, :m], tab[2, :m])
    if spec_i[SI_DCONST] != 0:
        return spec_f[SF_D]
    return spec_f[SF_DAMP] if t >= spec_f[SF_DTIME] else 0.0


@njit(cache=True)
def _field(t: float, z: Any, want_jac: bool, ctx: Any, f_out: Any, j_out: Any) -> None:
    """F(t, z) into ``f_out`` and, with ``want_jac``, ∂F/∂z into ``j_out``: the inputs,
    the plant's jets, the loop kernel (as :meth:`CompiledLoop.rhs` and
    :meth:`CompiledLoop.state_jacobian` call them); ``ctx`` the settings and workspace."""
    jets, kernel, ints, ints_bd, flt, p_true, p_nom, spec_i, spec_f, tab, wk = ctx
    x, xi, rd, inputs, flags, pv, pj, tz, trd, tin, out, tout, tz0, trd0, tin0, tout0 = wk
    n, o_eso, rho, nz = spec_i[SI_N], spec_i[SI_OESO], spec_i[SI_RHO], spec_i[SI_NZ]
    dd = _inputs(t, spec_i, spec_f, tab, rd)
    need_bd = spec_i[SI_HASBD] != 0 and dd != 0.0
    for i in range(n):
        x[i] = z[i]
    for i in range(rho):
        xi[i] = z[o_eso + i]
    flags[0] = 1 if want_jac else 0
    flags[1] = 1 if need_bd else 0
    flags[2], flags[3] = spec_i[SI_MODEL], spec_i[SI_IOFL]
    pv[:] = 0.0
    pj[:, :] = 0.0
    jets(x, xi, p_true, p_nom, flags, pv, pj)
    inputs[0], inputs[1], inputs[2] = dd, 0.0, 0.0
    settings = ints_bd if need_bd else ints
    if want_jac:
        kernel(z, tz, rd, trd, inputs, tin, False, settings, flt, pv, pj, out, tout)
        for i in range(nz):
            for j in range(nz):
                j_out[i, j] = tout[i, j]
    else:
        kernel(z, tz0, rd, trd0, inputs, tin0, False, settings, flt, pv, pj, out, tout0)
    for i in range(nz):
        f_out[i] = out[i]


@njit(cache=True)
def _workspace(spec_i: Any, n_rows: int, n_cols: int, n_out: int) -> Any:
    n, rho, nz = spec_i[SI_N], spec_i[SI_RHO], spec_i[SI_NZ]
    return (
        np.empty(n),
        np.empty(rho),
        np.zeros(rho + 1),
        np.zeros(3),
        np.zeros(4, np.int64),
        np.zeros(n_rows),
        np.zeros((n_rows, n_cols)),
        np.eye(nz),
        np.zeros((rho + 1, nz)),
        np.zeros((3, nz)),
        np.empty(n_out),
        np.empty((n_out, nz)),
        np.zeros((nz, 0)),
        np.zeros((rho + 1, 0)),
        np.zeros((3, 0)),
        np.zeros((n_out, 0)),
    )


# ------------------------------------------------------------------------ the method
@njit(cache=True)
def _dense(t, t_old, h, y_old, q, out):  # fmt: skip
    """The collocation polynomial of the step from ``t_old`` (length h) at t."""
    x = (t - t_old) / h
    x2 = x * x
    x3 = x2 * x
    for i in range(y_old.size):
        out[i] = y_old[i] + q[i, 0] * x + q[i, 1] * x2 + q[i, 2] * x3


@njit(cache=True)
def _predict_factor(h_abs, h_abs_old, err, err_old):  # fmt: skip
    if err_old < 0.0 or h_abs_old < 0.0 or err == 0.0:
        multiplier = 1.0
    else:
        multiplier = h_abs / h_abs_old * (err_old / err) ** 0.25
    if err == 0.0:
        return math.inf
    return min(1.0, multiplier) * err**-0.25


def run_slice(jets, kernel, ints, ints_bd, flt, p_true, p_nom, spec_i, spec_f, tab, n_rows,
         n_cols, n_out, z0, t0, t1, rtol, atol, st, phi, dscale, split, ts_out, ys_out,
         qs_out):  # fmt: skip
    """Integrate the loop from (t0, z0) towards t1 by Radau IIA, at most ``ts_out.size - 1``
    steps (module docstring).

    Plain Python: compiled with its signature by
    :func:`aiofl.analysis.loop_radau.compiled_slice`.

    Parameters
    ----------
    jets, kernel
        The plant's compiled jets (:func:`aiofl.analysis.plant_jets.plant_jets`) and the
        loop kernel (:func:`aiofl.analysis.loop_kernel.loop_eval`), first-class functions.
    ints, ints_bd, flt, p_true, p_nom
        The loop kernel's integer settings (with and without the disturbance input's
        column), its float settings, the true and the nominal plant parameters.
    spec_i, spec_f, tab
        The inputs' kind and sizes, their float settings (``SF_*``) and their table (the
        reference's samples or Han's precomputed outputs).
    n_rows, n_cols, n_out
        The jets' rows and columns and the loop kernel's outputs (workspace sizes).
    z0, t0, t1
        The start state, the start time and the end time [s].
    rtol, atol
        The relative tolerance and the absolute one per state.
    st
        The solver's state, carried between slices: (h, h_old, error_old, t reached,
        status); a non-positive h selects the first step as scipy does.
    phi, dscale, split
        Φ in the scaled coordinates z / ``dscale``, advanced in place when it has columns,
        by ``split`` exponential-midpoint parts per step.
    ts_out, ys_out, qs_out
        The steps' times, states and collocation coefficients (dense output), filled.

    Returns
    -------
    int
        The number of steps stored in ``ts_out`` / ``ys_out`` / ``qs_out``.
    """
    nz = z0.size
    wk = _workspace(spec_i, n_rows, n_cols, n_out)
    args = (jets, kernel, ints, ints_bd, flt, p_true, p_nom, spec_i, spec_f, tab, wk)
    y = z0.copy()
    t = t0
    f = np.empty(nz)
    jac = np.empty((nz, nz))
    _field(t, y, False, args, f, jac)
    _field(t, y, True, args, np.empty(nz), jac)
    sc = np.empty(nz)
    if st[0] <= 0.0:  # scipy's select_initial_step, order 3
        interval = t1 - t
        for i in range(nz):
            sc[i] = atol[i] + abs(y[i]) * rtol
        d0, d1 = _rms(y / sc), _rms(f / sc)
        h0 = 1e-6 if (d0 < 1e-5 or d1 < 1e-5) else 0.01 * d0 / d1
        h0 = min(h0, interval)
        f1 = np.empty(nz)
        _field(t + h0, y + h0 * f, False, args, f1, np.empty((0, 0)))
        d2 = _rms((f1 - f) / sc) / h0
        small = d1 <= 1e-15 and d2 <= 1e-15
        h1 = max(1e-6, h0 * 1e-3) if small else (0.01 / max(d1, d2)) ** 0.25
        st[0], st[1], st[2] = min(100 * h0, h1, interval), -1.0, -1.0
    newton_tol = max(10 * EPS / rtol, min(0.03, rtol**0.5))
    eye = np.eye(nz)
    lu_r = np.empty((nz, nz))
    lu_c = np.empty((nz, nz), np.complex128)
    piv_r = np.empty(nz, np.int64)
    piv_c = np.empty(nz, np.int64)
    lu_valid = False
    current_jac = True
    have_sol = False
    t_prev, h_prev = 0.0, 1.0
    y_prev = np.empty(nz)
    q = np.zeros((nz, 3))
    z_stage = np.zeros((3, nz))
    z_new = np.zeros((3, nz))
    w = np.zeros((3, nz))
    dw = np.zeros((3, nz))
    f_st = np.empty((3, nz))
    yi = np.empty(nz)
    fr = np.empty(nz)
    fc = np.empty(nz, np.complex128)
    err_v = np.empty(nz)
    ze = np.empty(nz)
    zm = np.empty(nz)
    jm = np.empty((nz, nz))
    fm = np.empty(nz)
    max_steps = ts_out.size - 1
    steps = 0
    ts_out[0] = t
    ys_out[0, :] = y
    st[4] = RUNNING
    while t < t1:
        if steps >= max_steps:
            st[3] = t
            return steps
        min_step = 10 * abs(np.nextafter(t, np.inf) - t)
        if st[0] < min_step:
            h_abs, h_abs_old, err_old = min_step, -1.0, -1.0
        else:
            h_abs, h_abs_old, err_old = st[0], st[1], st[2]
        rejected = False
        accepted = False
        n_iter = 0
        rate = -1.0
        err = 0.0
        safety = 0.0
        t_new = t
        h = h_abs
        while not accepted:
            if h_abs < min_step:
                st[3], st[4] = t, TOO_SMALL
                return steps
            h = h_abs
            t_new = t + h
            if t_new > t1:
                t_new = t1
            h = t_new - t
            h_abs = abs(h)
            if have_sol:
                for i in range(3):
                    _dense(t + h * C[i], t_prev, h_prev, y_prev, q, yi)
                    for j in range(nz):
                        z_stage[i, j] = yi[j] - y[j]
            else:
                z_stage[:, :] = 0.0
            for i in range(nz):
                sc[i] = atol[i] + abs(y[i]) * rtol
            converged = False
            while not converged:
                if not lu_valid:
                    for i in range(nz):
                        for j in range(nz):
                            lu_r[i, j] = MU_REAL / h * eye[i, j] - jac[i, j]
                            lu_c[i, j] = MU_COMPLEX / h * eye[i, j] - jac[i, j]
                    _lu(lu_r, piv_r)
                    _lu(lu_c, piv_c)
                    lu_valid = True
                # the collocation system, simplified Newton in the transformed variables
                m_real = MU_REAL / h
                m_complex = MU_COMPLEX / h
                w[:, :] = TI @ z_stage
                z_new[:, :] = z_stage
                dw_norm_old = -1.0
                rate = -1.0
                converged = False
                k = 0
                for k in range(NEWTON_MAXITER):
                    finite = True
                    for i in range(3):
                        for j in range(nz):
                            yi[j] = y[j] + z_new[i, j]
                        _field(t + h * C[i], yi, False, args, fm, jm)
                        for j in range(nz):
                            f_st[i, j] = fm[j]
                            if not np.isfinite(fm[j]):
                                finite = False
                    if not finite:
                        break
                    for j in range(nz):
                        sr = 0.0
                        sc_ = 0j
                        for i in range(3):
                            sr += f_st[i, j] * TI[0, i]
                            sc_ += f_st[i, j] * complex(TI[1, i], TI[2, i])
                        fr[j] = sr - m_real * w[0, j]
                        fc[j] = sc_ - m_complex * complex(w[1, j], w[2, j])
                    _lu_solve(lu_r, piv_r, fr)
                    _lu_solve(lu_c, piv_c, fc)
                    s2 = 0.0
                    for j in range(nz):
                        dw[0, j] = fr[j]
                        dw[1, j] = fc[j].real
                        dw[2, j] = fc[j].imag
                        for i in range(3):
                            s2 += (dw[i, j] / sc[j]) ** 2
                    dw_norm = math.sqrt(s2 / (3 * nz))
                    if dw_norm_old >= 0.0:
                        rate = dw_norm / dw_norm_old
                    if rate >= 0.0 and (
                        rate >= 1
                        or rate ** (NEWTON_MAXITER - k) / (1 - rate) * dw_norm > newton_tol
                    ):
                        break
                    w += dw
                    z_new[:, :] = T @ w
                    if dw_norm == 0 or (rate >= 0.0 and rate / (1 - rate) * dw_norm < newton_tol):
                        converged = True
                        break
                    dw_norm_old = dw_norm
                n_iter = k + 1
                if not converged:
                    if current_jac:
                        break
                    _field(t, y, True, args, fm, jac)
                    current_jac = True
                    lu_valid = False
            if not converged:
                h_abs *= 0.5
                lu_valid = False
                continue
            for j in range(nz):
                s = 0.0
                for i in range(3):
                    s += z_new[i, j] * E[i]
                ze[j] = s / h
                err_v[j] = f[j] + ze[j]
            _lu_solve(lu_r, piv_r, err_v)
            for j in range(nz):
                sc[j] = atol[j] + max(abs(y[j]), abs(y[j] + z_new[2, j])) * rtol
            err = _rms(err_v / sc)
            safety = 0.9 * (2 * NEWTON_MAXITER + 1) / (2 * NEWTON_MAXITER + n_iter)
            if rejected and err > 1:
                _field(t, y + err_v, False, args, fm, jm)
                for j in range(nz):
                    err_v[j] = fm[j] + ze[j]
                _lu_solve(lu_r, piv_r, err_v)
                err = _rms(err_v / sc)
            if err > 1:
                factor = _predict_factor(h_abs, h_abs_old, err, err_old)
                h_abs *= max(MIN_FACTOR, safety * factor)
                lu_valid = False
                rejected = True
            else:
                accepted = True
        recompute_jac = n_iter > 2 and rate > 1e-3
        factor = min(MAX_FACTOR, safety * _predict_factor(h_abs, h_abs_old, err, err_old))
        if not recompute_jac and factor < 1.2:
            factor = 1.0
        else:
            lu_valid = False
        # the step: dense output, the new state and F there
        for i in range(nz):
            y_prev[i] = y[i]
            for c in range(3):
                q[i, c] = z_new[0, i] * P[0, c] + z_new[1, i] * P[1, c] + z_new[2, i] * P[2, c]
        t_prev, h_prev, have_sol = t, h, True
        for i in range(nz):
            y[i] = y[i] + z_new[2, i]
        _field(t_new, y, False, args, f, jm)
        if recompute_jac:
            _field(t_new, y, True, args, fm, jac)
            current_jac = True
        else:
            current_jac = False
        st[1] = st[0]
        st[2] = err
        st[0] = h_abs * factor
        if phi.shape[1] > 0:  # Φ by the exponential midpoint rule on this step
            for part in range(split):
                a = t_prev + h_prev * part / split
                b = t_prev + h_prev * (part + 1) / split if part + 1 < split else t_new
                tm = 0.5 * (a + b)
                _dense(tm, t_prev, h_prev, y_prev, q, zm)
                _field(tm, zm, True, args, fm, jm)
                for i in range(nz):
                    for j in range(nz):
                        jm[i, j] *= (b - a) * dscale[j] / dscale[i]
                phi[:, :] = _expm(jm) @ phi
        t = t_new
        steps += 1
        ts_out[steps] = t
        ys_out[steps, :] = y
        qs_out[steps - 1, :, :] = q
    st[3], st[4] = t, DONE
    return steps
