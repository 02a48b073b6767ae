r"""The compiled, batched closed-loop engine.

Plant, tracking differentiator, ESO, state error feedback, linearizing law and the
performance integrals form one ODE :math:`\dot z = F(t, z)`, integrated with fixed-step
RK4 (or forward Euler) inside one compiled numba function per plant, with no Python in the
time loop.  A call takes a *batch* of members (one row each of controller,
plant-parameter and scenario arrays); one simulation is a batch of one.  Members run in
parallel on ``numba.get_num_threads()`` threads: the compiled member function releases the
GIL and each thread claims the next unclaimed member, so a member that diverges early
frees its core at once.  Members are independent, so a member's numbers do not depend on
the batch it is in, the thread count or the scheduling (bitwise).

State of one member (only the active part is integrated)::

    z = [ x (n) | ITAE IAE ISE ISU IAU | TD state (0, 2 or ρ) | ESO state ξ̂ (ρ+1) ]

Component kinds come from the integer row (data), so every structure shares one compiled
function per plant.  A member whose state becomes non-finite or exceeds
``divergence_threshold`` stops; it is reported as diverged with the time, the others carry
on.  Trajectories are stored only when asked for, every ``decimation``-th step.

Piecewise-constant inputs (measurement noise, the step disturbance, the plant-parameter
change and a step reference) are held over each step at their value at its start, so the
integrator never straddles a jump inside a step: a switch on the time grid is exact, one
between grid points acts from the next step (see :data:`SWITCH_RTOL`).

The controller's formulas are not written here: the right-hand side calls the public scalar
component functions of :mod:`aiofl.components.differentiators` (TDs, prefilter),
:mod:`aiofl.components.feedback` (fal, NLSEF, INLSEF, linear SEF),
:mod:`aiofl.components.observers` (INLESO injection, ESO) and :mod:`aiofl.components.law` (AIOFL
and IOFL laws, saturation), bound into the kernel as compiled functions; per-member constants
(observer gains, fal slopes, prefilter coefficients, ITD constants) come from the same modules'
scalar functions.

Speed notes.  The time loop touches only thread-local memory reached through *unmanaged*
array views (no reference counting, see :func:`_unmanaged_intrinsic`), evaluates r(t) once
per distinct stage time, and passes scalars (or a whole array and an offset) to the component
functions, never slices.  The components skip the power function for exponents 0 and 1 and use
cheaper forms of tanh and :math:`|e|^a` that agree with libm to a few ulp
(:mod:`aiofl.components.fastmath`).  LLVM fast-math flags are on except ``nnan``/``ninf``
(divergence detection relies on IEEE NaN/inf).

Compilation.  The kernel is built from the template functions below with the plant's
compiled f, g, h, b_d bound as globals.  When every plant function comes from a source
file (built-in plants, user plants defined in a module or script), the compiled kernel is
cached on disk by numba under a name that carries a fingerprint of those files and of the
sources of the engine and of the component modules, so later processes load it instead of
compiling (about 6 s).  Set ``AIOFL_NO_CACHE=1`` to disable the cache.  A plant whose
functions are generated at run time (no source file) is compiled in every process.
"""

from __future__ import annotations

import contextlib
import hashlib
import itertools
import os
import sys
import threading
import types
from collections.abc import Sequence
from dataclasses import dataclass
from math import ceil
from typing import Any

import numpy as np
from numpy.typing import NDArray

from aiofl import layout as L
from aiofl.components.metrics import OPIWeights, opi
from aiofl.controller import Controller, ControllerBatch, controller_batch
from aiofl.plants.base import Plant
from aiofl.scenario import Scenario, noise_sequence

__all__ = ["BatchResult", "SimulationResult", "closed_loop_rhs", "simulate", "simulate_batch"]

# ----------------------------------------------------------------------------- layout
# Per-member packed parameters (thread-local inside the kernel): the controller's float row
# followed by quantities derived from it once per member.
Q_BETA = L.N_FLOAT  #: observer gains β_i = α_i ω0^i, i = 1..ρ+1
Q_LINK = Q_BETA + L.RHO_MAX + 1  #: feedback gains k_i (linear SEF / IOFL) or sef.k_i
Q_SLOPE = Q_LINK + L.RHO_MAX  #: fal inner slopes δ_i^(α_i - 1)
Q_PF = Q_SLOPE + L.RHO_MAX  #: linear prefilter coefficients ω^ρ, C(ρ,i) ω^(ρ-i)
Q_ITD_BC = Q_PF + L.RHO_MAX  #: b/c of the ITD
Q_ITD_GAIN = Q_ITD_BC + 1  #: (1 - a)/c of the ITD
N_Q = Q_ITD_BC + 2
# Per-member integers: kinds, ρ, m, offsets of the TD and ESO blocks in z, active length.
IQ_ESO, IQ_TD, IQ_SEF, IQ_LAW, IQ_RHO, IQ_M, IQ_OTD, IQ_OESO, IQ_NZ, IQ_NTD = range(10)
N_IQ = 10
N_SIG = 6  # t, r, y, y_meas, u, d
SWITCH_RTOL = 1e-12
"""A switching time t_s (step disturbance, parameter change, step reference) acts from the
first step whose start k·dt >= t_s (1 - SWITCH_RTOL): the tolerance absorbs the rounding of
k·dt, so a switch on the grid happens exactly at its step boundary."""


# Placeholders for the names a kernel instance binds (see _instantiate); the template
# functions below are plain Python until _build_kernel compiles them for one plant.
_N = 1  # plant states
_N_P = 1  # plant parameters
_NZ = 1  # longest member state
_PF = _PG = _PH = _PBD = _PNF = None  # the plant's compiled f, g, h, b_d, normal form
_SETUP = _REFERENCE = _DERIV = None  # sibling compiled functions
_UNMANAGED = _KEEP_ALIVE = None  # see _unmanaged_intrinsic
# the controller's component functions (see _component_functions)
_HAN_TD = _ITD = _ITD_CONSTANTS = _PREFILTER = _PREFILTER_COEF = None
_FAL = _FAL_SLOPE = _INLSEF_TERM = _INLSEF_LIMIT = _LINEAR_SEF = _LINEAR_SEF_GAIN = None
_ESO_GAIN = _ESO_UPDATE = _INLESO = _AIOFL_LAW = _IOFL_LAW = _SATURATE = None


def _tpl_setup(ip, fp, q, iq):  # pragma: no cover - compiled
    """Fill the packed per-member parameters ``q`` and integers ``iq`` from one member's
    integer row ``ip`` and float row ``fp``."""
    rho = ip[L.I_RHO]
    for i in range(L.N_FLOAT):
        q[i] = fp[i]
    for i in range(L.N_FLOAT, N_Q):
        q[i] = 0.0
    w0 = fp[L.F_OMEGA0]
    for i in range(rho + 1):
        q[Q_BETA + i] = _ESO_GAIN(fp[L.F_ALPHA + i], w0, i + 1)
    if ip[L.I_SEF] == L.SEF_LINEAR or ip[L.I_LAW] == L.LAW_IOFL:
        for i in range(rho):
            q[Q_LINK + i] = _LINEAR_SEF_GAIN(rho, i + 1, fp[L.F_SEF_OMEGA_C])
    else:
        for i in range(L.RHO_MAX):
            q[Q_LINK + i] = fp[L.F_SEF_K + i]
    for i in range(L.RHO_MAX):
        q[Q_SLOPE + i] = _FAL_SLOPE(fp[L.F_SEF_ALPHA + i], fp[L.F_SEF_DELTA + i])
    for i in range(rho):
        q[Q_PF + i] = _PREFILTER_COEF(rho, i + 1, fp[L.F_TD_OMEGA])
    q[Q_ITD_BC], q[Q_ITD_GAIN] = _ITD_CONSTANTS(fp[L.F_TD_A], fp[L.F_TD_B], fp[L.F_TD_C])
    td = ip[L.I_TD]
    if td == L.TD_EXACT:
        ntd = 0
    elif td == L.TD_LINEAR:
        ntd = rho
    else:
        ntd = 2
    iq[IQ_ESO] = ip[L.I_ESO]
    iq[IQ_TD] = td
    iq[IQ_SEF] = ip[L.I_SEF]
    iq[IQ_LAW] = ip[L.I_LAW]
    iq[IQ_RHO] = rho
    iq[IQ_M] = ip[L.I_NFB]
    iq[IQ_OTD] = _N + L.N_METRIC
    iq[IQ_OESO] = _N + L.N_METRIC + ntd
    iq[IQ_NZ] = _N + L.N_METRIC + ntd + rho + 1
    iq[IQ_NTD] = ntd


def _tpl_reference(t, t_hold, sc, ref_table, ref_row, out, oi, nd):  # pragma: no cover - compiled
    """r(t) and its derivatives 0..nd into ``out[oi]`` (nd > 0 only for the exact TD).

    ``t_hold`` is the start of the current step: a step reference is held over the step.
    """
    kind = int(sc[L.S_REF_KIND])
    for k in range(nd + 1):
        out[oi, k] = 0.0
    if kind == L.REF_SINE:
        a = sc[L.S_REF_A]
        w = sc[L.S_REF_OMEGA]
        ph = w * t + sc[L.S_REF_PHASE]
        sn = np.sin(ph)
        out[oi, 0] = a * sn + sc[L.S_REF_OFFSET]
        if nd > 0:
            cs = np.cos(ph)
            wk = a
            for k in range(1, nd + 1):  # d^k/dt^k sin = sin(ph + k π/2)
                wk *= w
                j = k % 4
                out[oi, k] = wk * (cs if j == 1 else (-sn if j == 2 else (-cs if j == 3 else sn)))
    elif kind == L.REF_STEP:
        # a step switches at a step boundary, like every piecewise-constant input
        on = t_hold >= sc[L.S_REF_TSTEP] * (1.0 - SWITCH_RTOL)
        out[oi, 0] = sc[L.S_REF_OFFSET] + (sc[L.S_REF_A] if on else 0.0)
    else:
        dtr = sc[L.S_REF_DT]
        ns = ref_table.shape[1]
        s = t / dtr
        k0 = int(s)
        if k0 >= ns - 1:
            out[oi, 0] = ref_table[ref_row, ns - 1]
        else:
            lo = ref_table[ref_row, k0]
            hi = ref_table[ref_row, k0 + 1]
            out[oi, 0] = lo + (s - k0) * (hi - lo)
            if nd >= 1:
                out[oi, 1] = (hi - lo) / dtr


def _tpl_deriv(t, z, dz, iq, q, p, p_nom, sc, rr, ri, noise_val, d, xb, sig):  # pragma: no cover
    """F(t, z) of one member: writes ``dz[:nz]`` and the signals r, y, y_meas, u, d.

    ``rr[ri]`` holds r(t) (and, for the exact TD, its derivatives); ``p`` is the true plant's
    parameter vector at t, ``p_nom`` the nominal one (for the IOFL law); ``noise_val`` and
    ``d`` are the measurement noise and the input disturbance (held over the step); ``xb``
    is scratch for the plant state.
    """
    rho = iq[IQ_RHO]
    m = iq[IQ_M]
    o_td = iq[IQ_OTD]
    o_eso = iq[IQ_OESO]
    td_kind = iq[IQ_TD]
    exact = td_kind == L.TD_EXACT
    for i in range(_N):
        xb[i] = z[i]

    # reference and the differentiator's profile r_1..r_rho; feed-forward r^(rho)
    r = rr[ri, 0]
    rff = 0.0
    if td_kind == L.TD_HAN:  # eq. (18)
        dz[o_td], dz[o_td + 1] = _HAN_TD(z[o_td], z[o_td + 1], r, q[L.F_TD_R])
    elif td_kind == L.TD_IMPROVED:  # eq. (21)
        dz[o_td], dz[o_td + 1] = _ITD(
            z[o_td], z[o_td + 1], r, q[Q_ITD_BC], q[Q_ITD_GAIN], q[L.F_TD_RHO]
        )
    elif td_kind == L.TD_LINEAR:
        rff = _PREFILTER(z, dz, o_td, rho, r, q, Q_PF)
    else:
        rff = rr[ri, rho]

    # plant output and measurement
    y = _PH(xb, p)
    y_meas = y + noise_val
    b0 = q[L.F_B0]

    # state error feedback and law; e_i = r_i - ξ̂_i
    if iq[IQ_LAW] == L.LAW_AIOFL:
        sef_kind = iq[IQ_SEF]
        if sef_kind == L.SEF_NONLINEAR:  # eq. (17)
            v = 0.0
            for i in range(m):
                ei = (rr[ri, i] if exact else z[o_td + i]) - z[o_eso + i]
                fe = _FAL(ei, q[L.F_SEF_ALPHA + i], q[L.F_SEF_DELTA + i], q[Q_SLOPE + i])
                v += q[L.F_SEF_K + i] * fe
        elif sef_kind == L.SEF_IMPROVED:  # eq. (20)
            acc = 0.0
            for i in range(m):
                ei = (rr[ri, i] if exact else z[o_td + i]) - z[o_eso + i]
                acc += _INLSEF_TERM(
                    ei, q[L.F_SEF_K + i], q[L.F_SEF_KB + i], q[L.F_SEF_MU + i], q[L.F_SEF_ALPHA + i]
                )
            v = _INLSEF_LIMIT(acc, q[L.F_SEF_DOUT])
        else:  # linear full-state feedback of the chain (14)
            acc = 0.0
            for i in range(m):
                acc += q[Q_LINK + i] * ((rr[ri, i] if exact else z[o_td + i]) - z[o_eso + i])
            v = _LINEAR_SEF(acc, rff, b0)
        u = _AIOFL_LAW(v, z[o_eso + rho], b0)  # eq. (14)
    else:  # classical IOFL on the nominal model
        nfx = _PNF(xb, p_nom)
        acc = rff
        for i in range(m):
            acc += q[Q_LINK + i] * ((rr[ri, i] if exact else z[o_td + i]) - nfx[i])
        u = _IOFL_LAW(acc, nfx[rho], nfx[rho + 1])
    u = _SATURATE(u, q[L.F_UMAX])

    # observer, eqs. (5)/(16) or (19)
    e = y_meas - z[o_eso]
    if iq[IQ_ESO] == L.ESO_IMPROVED:
        e = _INLESO(e, q[L.F_KA], q[L.F_KB], q[L.F_EA], q[L.F_EB])
    _ESO_UPDATE(z, dz, o_eso, rho, q, Q_BETA, b0, u, e)

    # plant
    fx = _PF(xb, p)
    gx = _PG(xb, p)
    for i in range(_N):
        dz[i] = fx[i] + gx[i] * u
    if d != 0.0:
        bdx = _PBD(xb, p)
        for i in range(_N):
            dz[i] += bdx[i] * d

    # performance integrals (eq. 22)
    err = abs(y - r)
    dz[_N + L.M_ITAE] = t * err
    dz[_N + L.M_IAE] = err
    dz[_N + L.M_ISE] = err * err
    dz[_N + L.M_ISU] = u * u
    dz[_N + L.M_IAU] = abs(u)
    sig[0] = r
    sig[1] = y
    sig[2] = y_meas
    sig[3] = u
    sig[4] = d


def _tpl_member(  # pragma: no cover - compiled
    mi,
    ints,
    floats,
    p_before,
    p_after,
    p_nom,
    scen,
    x0,
    ref_table,
    ref_row,
    noise_table,
    noise_row,
    dt,
    n_steps,
    method,
    decimation,
    store,
    threshold,
    metrics,
    status,
    t_div,
    traj,
):
    """Integrate member ``mi`` over the horizon; every array it touches in the time loop is
    its own (thread-local), so parallel members never share a cache line or a refcount."""
    # Every array the time loop touches is reached through an unmanaged view (see
    # _unmanaged): no reference counting in the loop, nothing shared between threads.
    nr = L.RHO_MAX + 2
    work_owner = np.zeros(N_Q + 4 * _NZ + _N + 5 + 4 * _N_P + L.N_SCEN)
    iq_owner = np.zeros(N_IQ, dtype=np.int64)
    rr_owner = np.zeros((3, nr))  # r and derivatives at t, t + dt/2, t + dt
    w = _UNMANAGED(work_owner)
    iq = _UNMANAGED(iq_owner)
    rrs = _UNMANAGED(rr_owner)
    ref_t = _UNMANAGED(ref_table)
    noise_t = _UNMANAGED(noise_table)
    tr = _UNMANAGED(traj)
    o = 0
    q = w[o : o + N_Q]
    o += N_Q
    z = w[o : o + _NZ]  # the state
    o += _NZ
    zt = w[o : o + _NZ]  # the state a stage is evaluated at
    o += _NZ
    kd = w[o : o + _NZ]  # F at the current stage
    o += _NZ
    acc = w[o : o + _NZ]  # k1 + 2 k2 + 2 k3 + k4
    o += _NZ
    xb = w[o : o + _N]  # plant state handed to f, g, h
    o += _N
    sig = w[o : o + 5]  # r, y, y_meas, u, d
    o += 5
    pb = w[o : o + _N_P]  # true plant parameters before / after the change
    o += _N_P
    pa = w[o : o + _N_P]
    o += _N_P
    pn = w[o : o + _N_P]  # nominal parameters (IOFL law)
    o += _N_P
    p = w[o : o + _N_P]  # true parameters now: pb, switched to pa at t_change
    o += _N_P
    sc = w[o : o + L.N_SCEN]
    _SETUP(ints[mi], floats[mi], q, iq)
    rho = iq[IQ_RHO]
    nza = iq[IQ_NZ]
    o_td = iq[IQ_OTD]
    o_eso = iq[IQ_OESO]
    ntd = iq[IQ_NTD]
    exact = iq[IQ_TD] == L.TD_EXACT
    nd = rho if exact else 0
    for j in range(_N_P):
        pb[j] = p_before[mi, j]
        pa[j] = p_after[mi, j]
        pn[j] = p_nom[mi, j]
        p[j] = pb[j]
    for j in range(L.N_SCEN):
        sc[j] = scen[mi, j]
    rrow = ref_row[mi]
    nrow = noise_row[mi]
    n_noise = noise_table.shape[1]
    for i in range(_N):
        z[i] = x0[mi, i]
        zt[i] = z[i]
    switched = False
    std = sc[L.S_NOISE_STD]
    hold = sc[L.S_NOISE_HOLD]
    t_change = sc[L.S_PCHANGE_TIME]
    n_stages = 4 if method == L.METHOD_RK4 else 1
    hdt = 0.5 * dt
    sixth = dt / 6.0
    status[mi] = L.STATUS_OK
    t_div[mi] = np.nan
    row = 0
    save_in = 0
    step_ref = sc[L.S_REF_KIND] == L.REF_STEP
    t_dist = sc[L.S_DIST_TIME] * (1.0 - SWITCH_RTOL)
    t_change *= 1.0 - SWITCH_RTOL
    for k in range(n_steps + 1):
        t = k * dt
        # r(t): RK4 carries it over from the previous step's t + dt (not a held step)
        if k == 0 or n_stages == 1 or step_ref:
            _REFERENCE(t, t, sc, ref_t, rrow, rrs, 0, nd)
        # piecewise-constant inputs are held over the step, switching at its start
        noise_val = 0.0
        if std > 0.0:  # held over [i hold, (i+1) hold)
            idx = int(t / hold + 1e-9)
            noise_val = std * noise_t[nrow, idx if idx < n_noise else n_noise - 1]
        d = sc[L.S_DIST_AMP] if t >= t_dist else 0.0
        if not switched and t >= t_change:
            for j in range(_N_P):
                p[j] = pa[j]
            switched = True
        for s in range(n_stages):
            if s == 0:
                ts = t
                ri = 0
            elif s == 3:
                ts = (k + 1) * dt
                ri = 2
            else:
                ts = (k + 0.5) * dt
                ri = 1
                if s == 1:
                    _REFERENCE(ts, t, sc, ref_t, rrow, rrs, 1, nd)
                    _REFERENCE((k + 1) * dt, t, sc, ref_t, rrow, rrs, 2, nd)
            _DERIV(ts, zt, kd, iq, q, p, pn, sc, rrs, ri, noise_val, d, xb, sig)
            if s == 0:
                if store and save_in == 0:
                    tr[mi, row, 0] = t
                    for j in range(5):
                        tr[mi, row, 1 + j] = sig[j]
                    for j in range(_N):
                        tr[mi, row, N_SIG + j] = z[j]
                    c0 = N_SIG + _N
                    for j in range(L.RHO_MAX + 1):
                        tr[mi, row, c0 + j] = z[o_eso + j] if j <= rho else 0.0
                    c0 += L.RHO_MAX + 1
                    for j in range(L.RHO_MAX):
                        val = 0.0
                        if exact and j < rho:
                            val = rrs[0, j]
                        elif j < ntd:
                            val = z[o_td + j]
                        tr[mi, row, c0 + j] = val
                    row += 1
                    save_in = decimation
                save_in -= 1
                if k == n_steps:
                    break
                if n_stages == 1:  # forward Euler
                    for j in range(nza):
                        z[j] += dt * kd[j]
                        zt[j] = z[j]
                else:
                    for j in range(nza):
                        acc[j] = kd[j]
                        zt[j] = z[j] + hdt * kd[j]
            elif s == 1:
                for j in range(nza):
                    acc[j] += 2.0 * kd[j]
                    zt[j] = z[j] + hdt * kd[j]
            elif s == 2:
                for j in range(nza):
                    acc[j] += 2.0 * kd[j]
                    zt[j] = z[j] + dt * kd[j]
            else:
                for j in range(nza):
                    z[j] += sixth * (acc[j] + kd[j])
                    zt[j] = z[j]
                for j in range(nd + 1):
                    rrs[0, j] = rrs[2, j]
        if k == n_steps:
            break
        bad = False
        for j in range(nza):
            if not abs(z[j]) < threshold:  # also catches NaN
                bad = True
        if bad:
            status[mi] = L.STATUS_DIVERGED
            t_div[mi] = (k + 1) * dt
            break
    for j in range(L.N_METRIC):
        metrics[mi, j] = z[_N + j]
    if store:
        for rw in range(row, tr.shape[1]):
            for j in range(tr.shape[2]):
                tr[mi, rw, j] = np.nan
    _KEEP_ALIVE(work_owner, iq_owner, rr_owner)  # the owners outlive their views


def _tpl_keep_alive(a, b, c):  # pragma: no cover - compiled
    """A use of the arrays that own the memory of unmanaged views, so they live until here."""
    return a.size + b.size + c.size


def _tpl_eval(
    ints, floats, p, p_nom, scen, ref_table, t, z, noise_val, dz, sig
):  # pragma: no cover
    """One evaluation of F(t, z) for member 0 (for cross-checks, see closed_loop_rhs)."""
    q = np.empty(N_Q)
    iq = np.empty(N_IQ, dtype=np.int64)
    _SETUP(ints[0], floats[0], q, iq)
    rr = np.zeros((1, L.RHO_MAX + 2))
    nd = iq[IQ_RHO] if iq[IQ_TD] == L.TD_EXACT else 0
    _REFERENCE(t, t, scen[0], ref_table, 0, rr, 0, nd)
    xb = np.zeros(_N)
    sc = scen[0]
    d = sc[L.S_DIST_AMP] if t >= sc[L.S_DIST_TIME] * (1.0 - SWITCH_RTOL) else 0.0
    _DERIV(t, z, dz, iq, q, p, p_nom, sc, rr, 0, noise_val, d, xb, sig)
    return iq[IQ_OTD], iq[IQ_OESO], iq[IQ_NZ]


# ----------------------------------------------------------------------- compilation
@dataclass(frozen=True)
class _Kernel:
    """The compiled functions of one plant."""

    member: Any  # integrates one member of a batch (releases the GIL)
    evaluate: Any  # one F(t, z) evaluation (compiled lazily by closed_loop_rhs)
    n_cols: int
    cached: bool


_KERNELS: dict[int, tuple[Plant, _Kernel]] = {}
_KERNELS_LOCK = threading.Lock()


def _source_digest(path: str) -> str:
    with open(path, "rb") as fh:
        return hashlib.sha256(fh.read()).hexdigest()


def _function_fingerprint(fn: Any) -> str | None:
    """What identifies a plant function's code for the on-disk kernel cache, or None if it
    cannot be identified (no source file, or a closure over non-scalar values)."""
    fn = getattr(fn, "py_func", fn)
    code = getattr(fn, "__code__", None)
    if code is None:
        return None
    path = code.co_filename
    if not os.path.isfile(path):
        return None
    extra: list[Any] = []
    for cell in fn.__closure__ or ():
        val = cell.cell_contents
        if not isinstance(val, (int, float, str, bool, tuple)):
            return None
        extra.append(repr(val))
    if fn.__defaults__:
        extra.append(repr(fn.__defaults__))
    return "|".join([path, fn.__qualname__, _source_digest(path), *extra])


def _kernel_fingerprint(plant: Plant) -> str | None:
    """A digest of everything the compiled kernel of ``plant`` depends on, or None if a
    plant function cannot be fingerprinted (the kernel is then compiled every process)."""
    parts = [sys.version, __import__("numba").__version__, str(plant.n_states)]
    for mod in (L, sys.modules[__name__], *_component_modules()):
        parts.append(_source_digest(mod.__file__))
    for fname in ("f", "g", "h", "bd", "normal_form"):
        fn = getattr(plant, fname)
        if fn is None:
            parts.append(f"{fname}=None")
            continue
        fp = _function_fingerprint(fn)
        if fp is None:
            return None
        parts.append(f"{fname}={fp}")
    return hashlib.sha256("\n".join(parts).encode()).hexdigest()[:20]


def _component_modules() -> tuple[Any, ...]:
    """The modules whose compiled functions the kernel calls (their sources are part of the
    kernel's cache fingerprint)."""
    from aiofl.components import differentiators, fastmath, feedback, law, observers

    return fastmath, feedback, observers, differentiators, law


def _component_functions() -> dict[str, Any]:
    """The controller's component functions, by the global name the templates use."""
    from aiofl.components import differentiators as td
    from aiofl.components import feedback as fb
    from aiofl.components import law
    from aiofl.components import observers as ob

    return {
        "_HAN_TD": td.han_td_rhs,
        "_ITD": td.improved_td_rhs_scaled,
        "_ITD_CONSTANTS": td.improved_td_constants,
        "_PREFILTER": td.linear_prefilter_update,
        "_PREFILTER_COEF": td.linear_prefilter_coefficient,
        "_FAL": fb.fal_scaled,
        "_FAL_SLOPE": fb.fal_inner_slope,
        "_INLSEF_TERM": fb.inlsef_term,
        "_INLSEF_LIMIT": fb.inlsef_limit,
        "_LINEAR_SEF": fb.linear_sef,
        "_LINEAR_SEF_GAIN": fb.linear_sef_gain,
        "_ESO_GAIN": ob.eso_gain,
        "_ESO_UPDATE": ob.eso_update,
        "_INLESO": ob.inleso_injection,
        "_AIOFL_LAW": law.aiofl_law,
        "_IOFL_LAW": law.iofl_law,
        "_SATURATE": law.saturate,
    }


def _instantiate(tpl: Any, ns: dict[str, Any], suffix: str, **jit_options: Any) -> Any:
    """Compile template ``tpl`` with the globals ``ns`` (which bind one plant's functions).

    The qualified name carries the plant fingerprint so that numba's on-disk cache keeps
    one entry per plant (its index is keyed by file and qualified name).
    """
    from numba import njit

    fn = types.FunctionType(tpl.__code__, ns, tpl.__name__, tpl.__defaults__, None)
    fn.__qualname__ = f"{tpl.__name__}_{suffix}"
    fn.__doc__ = tpl.__doc__
    return njit(**jit_options)(fn)


def _build_kernel(plant: Plant, *, cache: bool | None = None) -> _Kernel:
    """Compile the closed-loop functions for one plant (see the module notes)."""

    f, g, h, bd, nf = plant.compiled
    fingerprint = _kernel_fingerprint(plant)
    use_cache = _cache_enabled() if cache is None else cache
    use_cache = use_cache and fingerprint is not None
    n = plant.n_states
    ns = dict(globals())
    ns.update(
        _N=n,
        _N_P=len(plant.params),
        _NZ=n + L.N_METRIC + 2 * L.RHO_MAX + 1,
        _PF=f,
        _PG=g,
        _PH=h,
        _PBD=bd,
        _PNF=nf,
        **_component_functions(),
    )
    # the plant's identity (stable across edits) + the fingerprint of its code
    ident = "|".join(
        [plant.name, str(n)]
        + [getattr(getattr(plant, k), "__qualname__", "-") for k in ("f", "g", "h", "bd")]
    )
    plant_key = hashlib.sha256(ident.encode()).hexdigest()[:8]
    suffix = f"{plant_key}_{fingerprint}" if fingerprint else f"nocache{id(plant):x}"
    from aiofl.components.fastmath import FASTMATH

    # the time loop is compiled with the components' fast-math flags and error model
    opts = {"fastmath": FASTMATH, "error_model": "numpy"}
    ns["_UNMANAGED"] = _unmanaged_intrinsic()
    ns["_KEEP_ALIVE"] = _instantiate(_tpl_keep_alive, ns, suffix)
    ns["_SETUP"] = _instantiate(_tpl_setup, ns, suffix, **opts)
    ns["_REFERENCE"] = _instantiate(_tpl_reference, ns, suffix, **opts)
    # one call site in the stage loop: inlined, so the compiler sees the whole step
    ns["_DERIV"] = _instantiate(_tpl_deriv, ns, suffix, inline="always", **opts)
    member = _instantiate(_tpl_member, ns, suffix, nogil=True, cache=use_cache, **opts)
    if use_cache:
        _prune_stale_cache(member, plant_key, suffix)
    evaluate = _instantiate(_tpl_eval, ns, suffix, **opts)
    n_cols = N_SIG + n + (L.RHO_MAX + 1) + L.RHO_MAX
    return _Kernel(member=member, evaluate=evaluate, n_cols=n_cols, cached=use_cache)


def _unmanaged_intrinsic() -> Any:
    """A numba intrinsic returning a view of an array without a memory-info pointer.

    numba reference-counts arrays with atomic increments whenever an array is passed to a
    compiled function or bound to a new name; in a loop that calls the plant's f, g and h
    four times per step this dominated the run time, and on a *shared* input array the
    atomics made parallel members contend for one cache line.  A view whose meminfo is
    NULL is never counted (numba's incref/decref return at once on NULL and LLVM removes
    them).  The caller must keep the owning array alive while the view is used (the
    kernel passes the owners to ``_KEEP_ALIVE`` after its loop).
    """
    from numba.core import cgutils
    from numba.core import types as nbtypes
    from numba.extending import intrinsic

    @intrinsic
    def unmanaged(typingctx: Any, arr: Any) -> Any:
        if not isinstance(arr, nbtypes.Array):
            return None

        def codegen(context: Any, builder: Any, sig: Any, args: Any) -> Any:
            src = context.make_array(sig.args[0])(context, builder, value=args[0])
            dst = context.make_array(sig.return_type)(context, builder)
            for name in ("nitems", "itemsize", "data", "shape", "strides"):
                setattr(dst, name, getattr(src, name))
            dst.meminfo = cgutils.get_null_value(dst.meminfo.type)
            dst.parent = cgutils.get_null_value(dst.parent.type)
            return dst._getvalue()

        return arr(arr), codegen

    return unmanaged


def _prune_stale_cache(member: Any, plant_key: str, suffix: str) -> None:
    """Delete this plant's cached kernels from older versions of its code or the engine's
    (same plant key, other fingerprint), so the cache does not grow with every edit."""
    cache_dir = getattr(getattr(member, "_cache", None), "_cache_path", None)
    if not cache_dir or not os.path.isdir(cache_dir):
        return
    prefix = f"{__name__.rsplit('.', 1)[-1]}._tpl_member_{plant_key}_"
    keep = f"{prefix}{suffix.split('_', 1)[1]}"
    for entry in os.scandir(cache_dir):
        if entry.name.startswith(prefix) and not entry.name.startswith(keep):
            with contextlib.suppress(OSError):  # another process may have removed it
                os.remove(entry.path)


def _cache_enabled() -> bool:
    """On-disk kernel cache, on unless ``AIOFL_NO_CACHE=1`` (or numba's caching is off)."""
    return os.environ.get("AIOFL_NO_CACHE", "") not in ("1", "true", "yes")


def kernel_for(plant: Plant) -> _Kernel:
    """The compiled kernel of ``plant`` (built on first use, then reused in this process;
    across processes numba's on-disk cache skips the compilation of built-in and
    file-defined plants)."""
    key = id(plant)
    with _KERNELS_LOCK:  # two threads asking for a new plant's kernel build it once
        if key not in _KERNELS or _KERNELS[key][0] is not plant:
            _KERNELS[key] = (plant, _build_kernel(plant))
        return _KERNELS[key][1]


def _run_members(member: Any, n_members: int, *args: Any) -> None:
    """Run ``member(i, *args)`` for every member, on ``numba.get_num_threads()`` threads.

    The compiled member function releases the GIL, so Python threads run members truly in
    parallel; each thread takes the next unclaimed member (dynamic scheduling, so members
    that diverge early do not leave a core idle).  Members are independent: the numbers do
    not depend on the thread count or on which thread ran which member.
    """
    import numba

    n_threads = max(1, min(numba.get_num_threads(), n_members))
    if n_threads == 1:
        for i in range(n_members):
            member(i, *args)
        return
    claim = itertools.count()  # next() on a count is atomic under the GIL
    errors: list[BaseException] = []

    def work() -> None:
        try:
            while not errors:
                i = next(claim)
                if i >= n_members:
                    return
                member(i, *args)
        except BaseException as exc:  # pragma: no cover - re-raised below
            errors.append(exc)

    threads = [threading.Thread(target=work, daemon=True) for _ in range(n_threads - 1)]
    for th in threads:
        th.start()
    work()
    for th in threads:
        th.join()
    if errors:
        raise errors[0]


# ---------------------------------------------------------------------------- results
@dataclass(frozen=True)
class SimulationResult:
    """One member's result.

    Attributes
    ----------
    metrics
        ``itae, iae, ise, isu, iau`` over the horizon (None if diverged).
    diverged, diverged_at
        Whether the member diverged, and when [s].
    t, signals
        Saved time points and a dict of signals by column name (``r, y, y_meas, u, d,
        x1.., xi_hat1.., r1..``); empty if trajectories were not stored.
    """

    metrics: dict[str, float] | None
    diverged: bool
    diverged_at: float | None
    t: NDArray[np.float64]
    signals: dict[str, NDArray[np.float64]]

    def opi(self, weights: OPIWeights | None = None) -> float | None:
        """OPI (eq. 22) of this run, or None if it diverged."""
        if self.metrics is None:
            return None
        m = self.metrics
        return float(opi(m["itae"], m["isu"], m["iau"], weights))

    def __getitem__(self, name: str) -> NDArray[np.float64]:
        return self.signals[name]


@dataclass(frozen=True)
class BatchResult:
    """Results of a batch: ``metrics`` (B, 5) by :data:`aiofl.layout.METRIC_NAMES`,
    ``diverged`` (B,), ``diverged_at`` (B,) [s, NaN if not], ``trajectories`` (B, T, C)
    or None, with ``columns`` naming C."""

    metrics: NDArray[np.float64]
    diverged: NDArray[np.bool_]
    diverged_at: NDArray[np.float64]
    trajectories: NDArray[np.float64] | None
    columns: tuple[str, ...]
    dt: float

    def __len__(self) -> int:
        return int(self.metrics.shape[0])

    def metric(self, name: str) -> NDArray[np.float64]:
        """One metric for every member (NaN where the member diverged)."""
        col = self.metrics[:, L.METRIC_NAMES.index(name)].copy()
        col[self.diverged] = np.nan
        return col

    def opi(self, weights: OPIWeights | None = None) -> NDArray[np.float64]:
        """OPI (eq. 22) of every member (NaN where the member diverged)."""
        return np.asarray(opi(self.metric("itae"), self.metric("isu"), self.metric("iau"), weights))

    def member(self, i: int) -> SimulationResult:
        """Member ``i`` as a :class:`SimulationResult` (trajectory cut at divergence)."""
        div = bool(self.diverged[i])
        mets = (
            None
            if div
            else {k: float(v) for k, v in zip(L.METRIC_NAMES, self.metrics[i], strict=True)}
        )
        t_div = float(self.diverged_at[i]) if div else None
        if self.trajectories is None:
            return SimulationResult(mets, div, t_div, np.empty(0), {})
        tr = self.trajectories[i]
        tr = tr[~np.isnan(tr[:, 0])]
        sig = {c: tr[:, j] for j, c in enumerate(self.columns) if c != "t"}
        return SimulationResult(mets, div, t_div, tr[:, 0], sig)


# ------------------------------------------------------------------------------- API
def _as_list(x: Any, n: int, what: str) -> list[Any]:
    if isinstance(x, (list, tuple)):
        if len(x) not in (1, n):
            raise ValueError(f"{len(x)} {what} for a batch of {n}")
        return list(x) * (n if len(x) == 1 else 1)
    return [x] * n


def simulate_batch(
    plant: Plant,
    controllers: Controller | Sequence[Controller] | ControllerBatch,
    scenarios: Scenario | Sequence[Scenario],
    *,
    dt: float = 1e-4,
    method: str = "rk4",
    store: bool = False,
    decimation: int = 10,
    divergence_threshold: float = 1e10,
) -> BatchResult:
    """Simulate a batch of closed loops in one compiled, parallel call.

    Parameters
    ----------
    plant
        The plant (its kernel is compiled on first use and cached).
    controllers
        One controller, a sequence (one per member) or a packed :class:`ControllerBatch`.
    scenarios
        One scenario for all members, or one per member; all share ``t_final``.
    dt
        Fixed step [s].
    method
        ``"rk4"`` or ``"euler"``.
    store, decimation
        Store trajectories, every ``decimation``-th step.
    divergence_threshold
        A member whose state leaves ``|z| < threshold`` (or becomes NaN) is stopped and
        reported as diverged.

    Returns
    -------
    BatchResult
    """
    if method not in L.METHODS:
        raise ValueError(f"method = {method!r}; allowed: {', '.join(L.METHODS)}")
    if not dt > 0:
        raise ValueError(f"dt = {dt}; allowed: > 0")
    if decimation < 1:
        raise ValueError(f"decimation = {decimation}; allowed: >= 1")
    batch = (
        controllers
        if isinstance(controllers, ControllerBatch)
        else controller_batch(
            controllers if isinstance(controllers, Controller) else list(controllers)
        )
    )
    b = len(batch)
    scens = _as_list(scenarios, b, "scenarios")
    t_final = scens[0].t_final
    if any(abs(s.t_final - t_final) > 1e-12 for s in scens):
        raise ValueError("all scenarios in one batch must share t_final")
    n_steps = round(t_final / dt)
    n = plant.n_states

    # per-scenario tables (computed once per distinct scenario)
    uniq: dict[int, int] = {}
    for s in scens:
        uniq.setdefault(id(s), len(uniq))
    distinct = list({id(s): s for s in scens}.values())
    rows = np.array([uniq[id(s)] for s in scens], dtype=np.int64)
    p_nom_vec = plant.param_vector()
    p_nom = np.repeat(p_nom_vec[None, :], b, axis=0)
    p_before_d = np.stack([p_nom_vec for _ in distinct])
    p_after_d = np.stack([plant.param_vector(s.plant_overrides, s.plant_scale) for s in distinct])
    # a change at t = 0 applies from the start
    scen_d = np.stack([s.row() for s in distinct])
    x0_d = np.zeros((len(distinct), n))
    for j, s in enumerate(distinct):
        if s.x0:
            if len(s.x0) != n:
                raise ValueError(f"scenario.x0 has {len(s.x0)} entries; plant has {n} states")
            x0_d[j] = s.x0
    n_noise = max(ceil(t_final / s.noise_hold) + 2 for s in distinct)
    noise_d = np.stack(
        [
            noise_sequence(s.noise_seed, n_noise) if s.noise_variance > 0 else np.zeros(n_noise)
            for s in distinct
        ]
    )
    n_ref = max([len(s.reference.samples) for s in distinct] + [2])
    ref_d = np.zeros((len(distinct), n_ref))
    for j, s in enumerate(distinct):
        if s.reference.samples:
            ref_d[j, : len(s.reference.samples)] = s.reference.samples
            ref_d[j, len(s.reference.samples) :] = s.reference.samples[-1]

    kernel = kernel_for(plant)
    n_save = n_steps // decimation + 1 if store else 0
    traj = np.empty((b, n_save, kernel.n_cols))  # rows after a divergence are set to NaN
    metrics = np.zeros((b, L.N_METRIC))
    status = np.zeros(b, dtype=np.int64)
    t_div = np.zeros(b)
    _run_members(
        kernel.member,
        b,
        batch.ints,
        batch.floats,
        np.ascontiguousarray(p_before_d[rows]),
        np.ascontiguousarray(p_after_d[rows]),
        p_nom,
        np.ascontiguousarray(scen_d[rows]),
        np.ascontiguousarray(x0_d[rows]),
        ref_d,
        rows,
        noise_d,
        rows,
        float(dt),
        n_steps,
        L.METHODS[method],
        int(decimation),
        bool(store),
        float(divergence_threshold),
        metrics,
        status,
        t_div,
        traj,
    )
    return BatchResult(
        metrics=metrics,
        diverged=status == L.STATUS_DIVERGED,
        diverged_at=t_div,
        trajectories=traj if store else None,
        columns=L.trajectory_columns(n),
        dt=float(dt),
    )


def simulate(
    plant: Plant,
    controller: Controller,
    scenario: Scenario,
    *,
    dt: float = 1e-4,
    method: str = "rk4",
    store: bool = True,
    decimation: int = 10,
    divergence_threshold: float = 1e10,
) -> SimulationResult:
    """Simulate one closed loop (a batch of one). See :func:`simulate_batch`."""
    res = simulate_batch(
        plant,
        controller,
        scenario,
        dt=dt,
        method=method,
        store=store,
        decimation=decimation,
        divergence_threshold=divergence_threshold,
    )
    return res.member(0)


def closed_loop_rhs(
    plant: Plant,
    controller: Controller,
    scenario: Scenario,
    t: float,
    x: Sequence[float],
    td: Sequence[float] = (),
    xi: Sequence[float] = (),
    *,
    noise: float = 0.0,
    changed: bool = False,
) -> dict[str, Any]:
    """One evaluation of the engine's compiled right-hand side :math:`F(t, z)`.

    For cross-checks against an independent implementation (:mod:`aiofl.engine.reference`):
    the same compiled code the time loop runs, at a chosen state.

    Parameters
    ----------
    plant, controller, scenario
        As for :func:`simulate`.
    t
        Time [s].
    x, td, xi
        Plant state (n), differentiator state (0, 2 or ρ entries; missing ones are 0) and
        observer state ξ̂ (ρ+1 entries; missing ones are 0).
    noise
        Measurement noise added to y at this instant.
    changed
        Use the changed plant parameters (``scenario.plant_scale``/``plant_overrides``).

    Returns
    -------
    dict
        ``dx``, ``dtd``, ``dxi``, ``dmetrics`` (ITAE, IAE, ISE, ISU, IAU integrands) and the
        signals ``r``, ``y``, ``y_meas``, ``u``, ``d``.
    """
    kernel = kernel_for(plant)
    n = plant.n_states
    rho = controller.rho
    n_td = {"exact": 0, "han": 2, "improved": 2, "linear": rho}[controller.td]
    batch = controller_batch(controller)
    p_nom = plant.param_vector()
    p = plant.param_vector(scenario.plant_overrides, scenario.plant_scale) if changed else p_nom
    samples = list(scenario.reference.samples) or [0.0, 0.0]
    nz = n + L.N_METRIC + 2 * L.RHO_MAX + 1
    z = np.zeros(nz)
    z[:n] = np.asarray(x, dtype=float)
    o_td = n + L.N_METRIC
    o_eso = o_td + n_td
    td_v = np.asarray(td, dtype=float)
    xi_v = np.asarray(xi, dtype=float)
    if td_v.size > n_td or xi_v.size > rho + 1:
        raise ValueError(f"td has at most {n_td} entries and xi at most {rho + 1}")
    z[o_td : o_td + td_v.size] = td_v
    z[o_eso : o_eso + xi_v.size] = xi_v
    dz = np.zeros(nz)
    sig = np.zeros(5)
    kernel.evaluate(
        batch.ints,
        batch.floats,
        p,
        p_nom,
        scenario.row()[None, :],
        np.asarray([samples], dtype=float),
        float(t),
        z,
        float(noise),
        dz,
        sig,
    )
    return {
        "dx": dz[:n].copy(),
        "dmetrics": dz[n : n + L.N_METRIC].copy(),
        "dtd": dz[o_td:o_eso].copy(),
        "dxi": dz[o_eso : o_eso + rho + 1].copy(),
        **dict(zip(("r", "y", "y_meas", "u", "d"), (float(v) for v in sig), strict=True)),
    }
