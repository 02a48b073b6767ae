r"""The continuous controller: its blocks in the stage right-hand side of the time loop.

A continuous member's closed loop is one ODE :math:`\dot z = F(t, z)`, with

    z = [ x (n) | ITAE IAE ISE ISU IAU | TD state (0, 2 or ρ) | ESO state ξ̂ (ρ+1) ]

(only the active part is integrated).  :func:`_tpl_deriv` is F for every lane of a group,
bound as the time loop's ``_RHS`` (:mod:`aiofl.engine.kernel.loop`); :func:`_tpl_setup` fills
the group's per-member constants; :func:`_tpl_store_controller` gives the trajectory's
observer and differentiator columns; :func:`_tpl_evaluate` evaluates F once at a given
state (:func:`aiofl.engine.simulation.closed_loop_rhs`, for cross-checks).

Component kinds are uniform within a group (the batch is grouped by kinds), so the
branches on kinds are taken here, outside the lane loops.  The classical IOFL law needs the
plant's normal form (an array per call), which cannot be vectorized: an IOFL group
evaluates its law lane by lane with :func:`aiofl.engine.kernel.member._iofl_command`.

This module's source is part of the cache fingerprint of every kernel.
"""

from __future__ import annotations

import numpy as np

from aiofl import layout as L
from aiofl.engine.kernel.loop import (
    N_S,
    S_AHAT,
    S_BHAT,
    S_D,
    S_E,
    S_NOISE,
    S_RFF,
    S_U,
    S_UC,
    S_UD,
    S_UDON,
    S_UREF,
    S_V,
    S_Y,
    S_YD,
    S_YDON,
    S_YM,
)
from aiofl.engine.kernel.member import (
    IQ_ESO,
    IQ_LAW,
    IQ_M,
    IQ_MODEL,
    IQ_NZ,
    IQ_OESO,
    IQ_OTD,
    IQ_RHO,
    IQ_SEF,
    IQ_TD,
    N_IQ,
    N_Q,
    Q_BETA,
    Q_FEEDBACK_GAIN,
    Q_PF,
    Q_SLOPE,
    SWITCH_RTOL,
)

# Placeholders: stand-ins so this module imports.  Filled per continuous instance by
# aiofl/engine/build/instances.py:recipe: the sizes, _MEMBER_SETUP (kernel.member._tpl_setup
# compiled for the instance) and _LEADING_ROWS (kernel.views.leading_rows_intrinsic()) by
# its ``ns.update``; _SETUP, _REFERENCE, _RHS and the lane blocks (kernel.lane_blocks
# ``_blk_*`` under their upper-case names) by its ``templates``.
_W = 32  # lane width: 32, or 1 for a lone member
_N = 1  # the plant's number of states
_NZ = 1  # the integrated state's rows
_MEMBER_SETUP = _SETUP = _LEADING_ROWS = _REFERENCE = _RHS = None
_BLK_HAN = _BLK_ITD = _BLK_PREFILTER_START = _BLK_PREFILTER_TERM = _BLK_COPY = None
_BLK_FILL = _BLK_OUTPUT = _BLK_ERROR = _BLK_FAL = _BLK_INLSEF = _BLK_LINEAR_TERM = None
_BLK_INLSEF_LIMIT = _BLK_LINEAR_SEF = _BLK_LAW = _BLK_IOFL = _BLK_ESO_ERROR = None
_BLK_INLESO_ERROR = _BLK_ESO_ROW = _BLK_ESO_INPUT = _BLK_ESO_LAST = _BLK_PLANT = None
_BLK_DISTURBANCE = _BLK_METRICS = _BLK_MODEL = _BLK_MODEL_LAW = _BLK_MODEL_INPUT = None
_BLK_PLANT_OUTPUT = None
PLACEHOLDERS = tuple(
    """
    _W _N _NZ _MEMBER_SETUP _SETUP _LEADING_ROWS _REFERENCE _RHS _BLK_HAN _BLK_ITD
    _BLK_PREFILTER_START _BLK_PREFILTER_TERM _BLK_COPY _BLK_FILL _BLK_OUTPUT _BLK_ERROR
    _BLK_FAL _BLK_INLSEF _BLK_LINEAR_TERM _BLK_INLSEF_LIMIT _BLK_LINEAR_SEF _BLK_LAW
    _BLK_IOFL _BLK_ESO_ERROR _BLK_INLESO_ERROR _BLK_ESO_ROW _BLK_ESO_INPUT _BLK_ESO_LAST
    _BLK_PLANT _BLK_DISTURBANCE _BLK_METRICS _BLK_MODEL _BLK_MODEL_LAW _BLK_MODEL_INPUT
    _BLK_PLANT_OUTPUT
    """.split()  # noqa: SIM905 - the names as a reader scans them
)
"""The names of the placeholder block: what the compile factory checks a recipe binds
when a template of this module reads one (:func:`aiofl.engine.build.compile.build`)."""


def _tpl_deriv(fns, t, z, dz, iq, q, p, pn, rr, ri, s, dany):  # pragma: no cover - compiled
    r"""F(t, z) of every lane: ``dz[:nz, l]`` and the signals y, y_meas, u in ``s``.

    In order: the differentiator's profile :math:`r_1..r_\rho` (Han's TD, eq. 18; the ITD,
    eq. 21; a linear prefilter; or the reference's exact derivatives ``rr[ri]``), the
    measurement :math:`y_m = h(x) + n`, the SEF (17), (20) or linear on
    :math:`e_i = r_i - \hat\xi_i` and the law :math:`u = v - \hat\xi_{\rho+1}/b_0`
    (14), saturated (or the classical IOFL law on the nominal model), the ESO (5)/(16) or
    (19) (model-assisted: its ρ-th equation and the law carry the nominal
    :math:`\hat\alpha + \hat\beta u` at :math:`\hat x = \Phi^{-1}(\hat\xi)`,
    :func:`aiofl.components.law.model_assisted_law`), the plant
    :math:`\dot x = f(x) + g(x)u + b_d(x)\tau_d` and the integrands of eq. (22).  Each
    formula is a lane block (:mod:`aiofl.engine.kernel.lane_blocks`)."""
    rho = iq[IQ_RHO]
    m = iq[IQ_M]
    o_td = iq[IQ_OTD]
    o_eso = iq[IQ_OESO]
    td_kind = iq[IQ_TD]
    exact = td_kind == L.TD_EXACT
    model = iq[IQ_MODEL] == L.ESO_MODEL_NOMINAL
    r = rr[ri, 0]
    rff = s[S_RFF]
    e = s[S_E]
    v = s[S_V]
    u = s[S_U]

    # reference profile r_1..r_rho and feed-forward r^(rho)
    if td_kind == L.TD_HAN:  # eq. (18)
        _BLK_HAN(z, dz[o_td], dz[o_td + 1], q, r, o_td, rff)
    elif td_kind == L.TD_IMPROVED:  # eq. (21)
        _BLK_ITD(z, dz[o_td], dz[o_td + 1], q, r, o_td, rff)
    elif td_kind == L.TD_LINEAR:
        _BLK_PREFILTER_START(z[o_td], q[Q_PF], r, rff)
        for i in range(1, rho):
            _BLK_PREFILTER_TERM(z[o_td + i], q[Q_PF + i], dz[o_td + i - 1], rff)
        _BLK_COPY(rff, dz[o_td + rho - 1])
    else:
        _BLK_COPY(rr[ri, rho], rff)

    _BLK_OUTPUT(fns, z, p, s[S_NOISE], s[S_Y], s[S_YM])
    for l in range(_W):  # a sensor delay: y(t - τ_out) + n(t) (_tpl_delay_stage_in)
        if s[S_YDON, l] != 0.0:
            s[S_YM, l] = s[S_YD, l] + s[S_NOISE, l]

    # state error feedback and law (kernel._aiofl_command), e_i = r_i - ξ̂_i
    if iq[IQ_LAW] == L.LAW_AIOFL:
        sef_kind = iq[IQ_SEF]
        _BLK_FILL(v, 0.0)
        for i in range(m):
            _BLK_ERROR(rr[ri, i] if exact else z[o_td + i], z[o_eso + i], e)
            if sef_kind == L.SEF_NONLINEAR:  # eq. (17)
                k, alpha = q[L.F_SEF_K + i], q[L.F_SEF_ALPHA + i]
                _BLK_FAL(k, alpha, q[L.F_SEF_DELTA + i], q[Q_SLOPE + i], e, v)
            elif sef_kind == L.SEF_IMPROVED:  # eq. (20)
                k, kb = q[L.F_SEF_K + i], q[L.F_SEF_KB + i]
                _BLK_INLSEF(k, kb, q[L.F_SEF_MU + i], q[L.F_SEF_ALPHA + i], e, v)
            else:
                _BLK_LINEAR_TERM(q[Q_FEEDBACK_GAIN + i], e, v)
        if sef_kind == L.SEF_IMPROVED:
            _BLK_INLSEF_LIMIT(q[L.F_SEF_V_LIMIT], v)
        elif sef_kind == L.SEF_LINEAR:
            _BLK_LINEAR_SEF(q[L.F_B0], rff, v)
        if model:  # the nominal normal form at x̂ = Φ⁻¹(ξ̂), then its law
            _BLK_MODEL(fns, z, o_eso, rho, pn, s[S_AHAT], s[S_BHAT])
            _BLK_MODEL_LAW(
                v, z[o_eso + rho], q[L.F_B0], s[S_AHAT], s[S_BHAT], q[L.F_UMIN], q[L.F_UMAX], u
            )
        else:
            _BLK_LAW(v, z[o_eso + rho], q[L.F_B0], q[L.F_UMIN], q[L.F_UMAX], u)
    else:
        _BLK_IOFL(fns, z, iq, q, pn, rr, ri, o_td, rff, u)

    # observer, eqs. (5)/(16) or (19)
    if iq[IQ_ESO] == L.ESO_IMPROVED:
        _BLK_INLESO_ERROR(
            s[S_YM],
            z[o_eso],
            q[L.F_ESO_K_ALPHA],
            q[L.F_ESO_K_BETA],
            q[L.F_ESO_G_ALPHA],
            q[L.F_ESO_G_BETA],
            e,
        )
    else:
        _BLK_ESO_ERROR(s[S_YM], z[o_eso], e)
    for i in range(rho):
        _BLK_ESO_ROW(z[o_eso + i + 1], q[Q_BETA + i], e, dz[o_eso + i])
    if model:  # dξ̂_ρ += α̂ + β̂ u
        _BLK_MODEL_INPUT(s[S_AHAT], s[S_BHAT], u, dz[o_eso + rho - 1])
    else:  # dξ̂_ρ += b0 u, eq. (5)
        _BLK_ESO_INPUT(q[L.F_B0], u, dz[o_eso + rho - 1])
    _BLK_ESO_LAST(q[Q_BETA + rho], e, dz[o_eso + rho])

    for l in range(_W):  # an input delay: the plant (and ISU) get u(t - τ_in), the ESO u(t)
        if s[S_UDON, l] != 0.0:
            s[S_UC, l] = u[l]
            u[l] = s[S_UD, l]
    dx = _LEADING_ROWS(dz, _N)
    _BLK_PLANT(fns, z, p, u, dx)
    if dany:
        _BLK_DISTURBANCE(fns, z, p, s[S_D], dx)
    m0 = _N
    du = dz[m0 : m0 + L.N_METRIC]
    _BLK_METRICS(t, s[S_Y], r, u, s[S_UREF], du[0], du[1], du[2], du[3], du[4])


def _tpl_delay_stage_in(k, st, n_stages, s, ring, dsteps):  # pragma: no cover - compiled
    r"""Transport delays of m steps, continuous: ``s[S_YD]`` is y at stage ``st`` of step
    k - m_out (y(0) while k < m_out), which the observer reads at stage ``st`` of step k;
    ``s[S_UD]`` the controller's command at stage ``st`` of step k - m_in (0 while
    k < m_in), which the plant gets.

    With the delays multiples of the step, the stage times of step k - m are those of
    step k shifted by τ, so the loop is the method of steps (Bellen & Zennaro, *Numerical
    Methods for Delay Differential Equations*, 2003, §3.1) with the integrator applied to
    the delayed copies of the state: the past stage values are exactly what that
    integrator computes for them, and its order is kept."""
    nb = ring.shape[1] // n_stages
    for l in range(_W):
        m = dsteps[1, l]
        if m > 0:
            s[S_YD, l] = ring[1, ((k - m) % nb) * n_stages + st, l] if k >= m else ring[1, 0, l]
        m = dsteps[0, l]
        s[S_UDON, l] = 1.0 if m > 0 else 0.0
        if m > 0:
            s[S_UD, l] = ring[0, ((k - m) % nb) * n_stages + st, l] if k >= m else 0.0


def _tpl_delay_stage_out(k, st, n_stages, s, ring, fns, z, p):  # pragma: no cover - compiled
    """y = h(x) at stage ``st`` of step k (at the state ``z``) and the controller's command
    there into the ring's slot."""
    nb = ring.shape[1] // n_stages
    slot = (k % nb) * n_stages + st
    _BLK_PLANT_OUTPUT(fns, z, p, ring[1, slot])
    for l in range(_W):
        ring[0, slot, l] = s[S_UC, l]


def _tpl_setup(lanes, batch, q, qt, iq, ctrl, nper):  # pragma: no cover - compiled
    """Per-lane constants ``q[:, l]`` of the group's members
    (:func:`aiofl.engine.kernel.member._tpl_setup`) and the group's ``iq`` (kinds and sizes are
    uniform within a group, so every lane writes the same); ``ctrl`` and ``nper`` (the
    sampled instance's) are unused."""
    for l in range(_W):
        _MEMBER_SETUP(batch.ints[lanes[l]], batch.floats[lanes[l]], qt, iq)
        for i in range(N_Q):
            q[i, l] = qt[i]


def _tpl_store_controller(which, j, rho, ntd, exact, l, z, iq, rrs, ctrl):  # pragma: no cover
    """Trajectory column j of lane l: the ESO estimate ξ̂_{j+1} (``which`` 0) or the
    differentiator's profile r_{j+1} (``which`` 1; the reference's derivative for the
    exact TD), 0 beyond the member's order."""
    if which == 0:
        return z[iq[IQ_OESO] + j, l] if j <= rho else 0.0
    if exact and j < rho:
        return rrs[0, j, l]
    if j < ntd:
        return z[iq[IQ_OTD] + j, l]
    return 0.0


def _tpl_evaluate(batch, t, zin, noise_val, dz_out, sig):  # pragma: no cover - compiled
    """F(t, z) of member 0 at the state ``zin`` (width-1 instance): ``dz_out`` and the
    signals r, y, y_meas, u, d into ``sig``; returns the TD and ESO offsets and the length
    of the active state."""
    nr = L.RHO_MAX + 2
    q = np.zeros((N_Q, 1))
    qt = np.zeros(N_Q)
    iq = np.zeros(N_IQ, dtype=np.int64)
    lanes = np.zeros(1, dtype=np.int64)
    _SETUP(lanes, batch, q, qt, iq, q, lanes)
    sc = np.zeros((L.N_SCEN, 1))
    for j in range(L.N_SCEN):
        sc[j, 0] = batch.scen[0, j]
    s = np.zeros((N_S, 1))
    rr = np.zeros((3, nr, 1))
    rrow = np.zeros(1, dtype=np.int64)
    nd = iq[IQ_RHO] if iq[IQ_TD] == L.TD_EXACT else 0
    _REFERENCE(t, t, sc, batch.ref_table, rrow, rr, 0, nd, int(sc[L.S_REF_KIND, 0]), s)
    z = np.zeros((_NZ, 1))
    dz = np.zeros((_NZ, 1))
    for i in range(_NZ):
        z[i, 0] = zin[i]
    n_p = batch.p_after.shape[1]
    p = np.zeros((n_p, 1))
    pn = np.zeros((n_p, 1))
    for j in range(n_p):
        p[j, 0] = batch.p_after[0, j]
        pn[j, 0] = batch.p_nom[0, j]
    s[S_NOISE, 0] = noise_val
    on = t >= sc[L.S_DIST_TIME, 0] * (1.0 - SWITCH_RTOL)
    s[S_D, 0] = sc[L.S_DIST_AMP, 0] if on else 0.0
    _RHS(batch.plant_table, t, z, dz, iq, q, p, pn, rr, 0, s, s[S_D, 0] != 0.0)
    for i in range(_NZ):
        dz_out[i] = dz[i, 0]
    sig[0] = rr[0, 0, 0]
    sig[1] = s[S_Y, 0]
    sig[2] = s[S_YM, 0]
    sig[3] = s[S_U, 0]
    sig[4] = s[S_D, 0]
    return iq[IQ_OTD], iq[IQ_OESO], iq[IQ_NZ]
