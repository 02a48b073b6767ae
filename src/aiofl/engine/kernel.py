r"""The closed-loop kernel templates: the right-hand side and the time loop of one member.

Plant, tracking differentiator, ESO, state error feedback, linearizing law and the
performance integrals form one ODE :math:`\dot z = F(t, z)`; :func:`_tpl_deriv` evaluates
it and :func:`_tpl_member` integrates it with fixed-step RK4 (or forward Euler) over the
horizon, with no Python in the time loop.  These functions are *templates*: plain Python
that reads the plant's compiled f, g, h, b_d, the controller's component functions and
the sizes as module globals (``_N``, ``_PF``, ``_FAL``, ...; placeholders here).
:mod:`aiofl.engine.build` copies their code into a namespace that binds one plant and
compiles it with numba.

State of one member (only the active part is integrated)::

    z = [ x (n) | ITAE IAE ISE ISU IAU | TD state (0, 2 or ρ) | ESO state ξ̂ (ρ+1) ]

Component kinds come from the integer row (data), so every structure shares one compiled
function per plant.  The plant starts at the scenario's x0, the differentiator at 0 and the
ESO at 0, or (``eso.init = "output"``) with :math:`\hat\xi_1(0) = y_m(0)`, the first
measurement.  The law's output is clipped to the actuator range :math:`[u_{min}, u_{max}]`
(``u_min`` NaN in the float row means :math:`-u_{max}`).  Divergence is data, not an
exception: a member whose state becomes non-finite or exceeds the threshold stops, with its
status set to diverged and the time recorded.  Trajectories are stored only when asked
for, every ``decimation``-th step.

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
scalar functions.  The dispatch over the SEF kinds and the laws is written once, in
:func:`_aiofl_command` and :func:`_iofl_command`, which the sampled controller
(:mod:`aiofl.engine.sampled`) calls too.

Speed notes.  The time loop touches only thread-local memory reached through *unmanaged*
array views (no reference counting, see :func:`aiofl.engine.views.unmanaged_intrinsic`),
evaluates r(t) once per distinct stage time, and passes scalars (or a whole array and an
offset) to the component functions, never slices.  The components skip the power function
for exponents 0 and 1 and use cheaper forms of tanh and :math:`|e|^a` that agree with libm to
a few ulp (:mod:`aiofl.components.fastmath`).  LLVM fast-math flags are on except
``nnan``/``ninf`` (divergence detection relies on IEEE NaN/inf).

This module's source is part of the on-disk cache fingerprint of every compiled kernel.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from aiofl import layout as L
from aiofl.components import feedback as _fb
from aiofl.components import law as _law
from aiofl.components.fastmath import FASTMATH

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
# Per-member integers: kinds, ρ, m, offsets of the TD and ESO blocks in z, active length,
# and how the ESO starts (layout.ESO_INIT_*).
IQ_ESO, IQ_TD, IQ_SEF, IQ_LAW, IQ_RHO, IQ_M, IQ_OTD, IQ_OESO, IQ_NZ, IQ_NTD, IQ_EINIT = range(11)
N_IQ = 11
N_SIG = 6  # t, r, y, y_meas, u, d
SWITCH_RTOL = 1e-12
"""A switching time t_s (step disturbance, parameter change, step reference) acts from the
first step whose start k·dt >= t_s (1 - SWITCH_RTOL): the tolerance absorbs the rounding of
k·dt, so a switch on the grid happens exactly at its step boundary."""


# Placeholders for the names a kernel instance binds (see aiofl.engine.build._instantiate):
# the template functions below are plain Python until aiofl.engine.build._build_kernel
# compiles them for one plant, with a copy of this module's globals as their globals.
_N = 1  # plant states
_N_P = 1  # plant parameters
_NZ = 1  # longest member state
_PF = _PG = _PH = _PBD = _PNF = None  # the plant's compiled f, g, h, b_d, normal form
_SETUP = _REFERENCE = _DERIV = None  # sibling compiled functions
_UNMANAGED = _KEEP_ALIVE = None  # see aiofl.engine.views
# the controller's component functions (see _component_functions)
_HAN_TD = _ITD = _ITD_CONSTANTS = _PREFILTER = _PREFILTER_COEF = None
_FAL = _FAL_SLOPE = _INLSEF_TERM = _INLSEF_LIMIT = _LINEAR_SEF = _LINEAR_SEF_GAIN = None
_ESO_GAIN = _ESO_UPDATE = _INLESO = _AIOFL_LAW = _IOFL_LAW = _SATURATE = None


# ------------------------------------------------------------ the law, written once
# The state error feedback and the law are the same formulas in the continuous loop
# (_tpl_deriv) and in the sampled controller (aiofl.engine.sampled): both call these two.
# They depend on no plant function, so they are compiled once, here, and inlined (numba IR
# inlining) where called, so each caller compiles to the code it had with them in place.
@njit(inline="always", fastmath=FASTMATH, error_model="numpy")
def _aiofl_command(iq, q, rr, ri, ref, o_ref, xh, o_x, rff):  # pragma: no cover - compiled
    r"""The AIOFL command before saturation: SEF (17), (20) or linear, then law (14).

    With :math:`e_i = r_i - \hat\xi_i`, i = 1..m, the nonlinear SEF (17)
    :math:`v = \sum_i k_i\,\mathrm{fal}(e_i, \alpha_i, \delta_i)`, the INLSEF (20)
    :math:`v = v_{lim}\tanh\big(\sum_i (k_i + k_{b,i}/(1 + e^{\mu_i e_i^2}))
    |e_i|^{\alpha_i}\operatorname{sign} e_i \,/\, v_{lim}\big)` or the linear feedback of
    the chain :math:`v = (\sum_i k_i e_i + r^{(\rho)})/b_0`, and
    :math:`u = v - \hat\xi_{\rho+1}/b_0` (14).

    :math:`r_i` is ``rr[ri, i-1]`` for the exact TD (the reference's derivatives), else
    ``ref[o_ref + i-1]`` (the differentiator's profile); :math:`\hat\xi_i` is
    ``xh[o_x + i-1]``; ``rff`` is :math:`r^{(\rho)}` (linear SEF only); per-member constants
    come from ``q``/``iq`` (:func:`_tpl_setup`).
    """
    rho = iq[IQ_RHO]
    m = iq[IQ_M]
    exact = iq[IQ_TD] == L.TD_EXACT
    b0 = q[L.F_B0]
    sef_kind = iq[IQ_SEF]
    if sef_kind == L.SEF_NONLINEAR:  # eq. (17)
        v = 0.0
        for i in range(m):
            ei = (rr[ri, i] if exact else ref[o_ref + i]) - xh[o_x + i]
            fe = _fb.fal_scaled(ei, q[L.F_SEF_ALPHA + i], q[L.F_SEF_DELTA + i], q[Q_SLOPE + i])
            v += q[L.F_SEF_K + i] * fe
    elif sef_kind == L.SEF_IMPROVED:  # eq. (20)
        acc = 0.0
        for i in range(m):
            ei = (rr[ri, i] if exact else ref[o_ref + i]) - xh[o_x + i]
            acc += _fb.inlsef_term(
                ei, q[L.F_SEF_K + i], q[L.F_SEF_KB + i], q[L.F_SEF_MU + i], q[L.F_SEF_ALPHA + i]
            )
        v = _fb.inlsef_limit(acc, q[L.F_SEF_DOUT])
    else:  # linear full-state feedback of the chain (14)
        acc = 0.0
        for i in range(m):
            acc += q[Q_LINK + i] * ((rr[ri, i] if exact else ref[o_ref + i]) - xh[o_x + i])
        v = _fb.linear_sef(acc, rff, b0)
    return _law.aiofl_law(v, xh[o_x + rho], b0)  # eq. (14)


@njit(inline="always", fastmath=FASTMATH, error_model="numpy")
def _iofl_command(iq, q, rr, ri, ref, o_ref, nfx, rff):  # pragma: no cover - compiled
    r"""The classical IOFL command on the nominal model, before saturation:
    :math:`u = (r^{(\rho)} + \sum_i k_i (r_i - \xi_i) - \alpha(x))/\beta(x)` with
    ``nfx`` = :math:`(\xi_1..\xi_\rho, \alpha, \beta)` of the plant's normal form and
    :math:`r_i`, ``rff`` as in :func:`_aiofl_command`."""
    rho = iq[IQ_RHO]
    exact = iq[IQ_TD] == L.TD_EXACT
    acc = rff
    for i in range(iq[IQ_M]):
        acc += q[Q_LINK + i] * ((rr[ri, i] if exact else ref[o_ref + i]) - nfx[i])
    return _law.iofl_law(acc, nfx[rho], nfx[rho + 1])


def _tpl_setup(ip, fp, q, iq):  # pragma: no cover - compiled
    """Fill the packed per-member parameters ``q`` and integers ``iq`` from one member's
    integer row ``ip`` and float row ``fp``."""
    rho = ip[L.I_RHO]
    for i in range(L.N_FLOAT):
        q[i] = fp[i]
    for i in range(L.N_FLOAT, N_Q):
        q[i] = 0.0
    if fp[L.F_UMIN] != fp[L.F_UMIN]:  # NaN: no lower limit given, the range is symmetric
        q[L.F_UMIN] = -fp[L.F_UMAX]
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
    iq[IQ_EINIT] = ip[L.I_ESO_INIT]


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
    o_td = iq[IQ_OTD]
    o_eso = iq[IQ_OESO]
    td_kind = iq[IQ_TD]
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
        u = _aiofl_command(iq, q, rr, ri, z, o_td, z, o_eso, rff)  # eqs. (14), (17)/(20)
    else:  # classical IOFL on the nominal model
        nfx = _PNF(xb, p_nom)
        u = _iofl_command(iq, q, rr, ri, z, o_td, nfx, rff)
    u = _SATURATE(u, q[L.F_UMIN], q[L.F_UMAX])  # actuator range [u_min, u_max]

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
    init_output = iq[IQ_EINIT] == L.ESO_INIT_OUTPUT
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
        if k == 0 and init_output:
            # ξ̂_1(0) = y_meas(0) = h(x(0)) + n(0), the first measurement; ξ̂_2.. stay 0
            for i in range(_N):
                xb[i] = z[i]
            z[o_eso] = _PH(xb, p) + noise_val
            zt[o_eso] = z[o_eso]
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
