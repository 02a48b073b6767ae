r"""The lane kernel: a group of members advanced together, one member per SIMD lane.

The members of a batch are independent copies of one program, so the engine runs them in
groups of W members (:data:`WIDTH` = 32 doubles, four AVX-512 registers; 1 for the few
members of a kind in a small batch): every quantity of a member becomes a column of a
(rows, W) array (structure of arrays) and every formula is applied in a loop over the W
lanes that LLVM vectorizes (:mod:`aiofl.engine.lane_blocks`).  This module holds the
*templates* of the time loop, the right-hand side and the reference, compiled per plant and
width like those of :mod:`aiofl.engine.kernel` (whose closed loop, layout, switching and
divergence semantics they follow exactly) by :mod:`aiofl.engine.lanes_build`.

**What makes it vectorize.**  A loop over lanes vectorizes only if its body is one basic
block of arithmetic after inlining: so each formula is a block (its own compiled function,
:mod:`aiofl.engine.lane_blocks`) with the component functions and the plant's f, g, h, b_d
inlined into its lane loop; component kinds are uniform within a group (a mixed batch is
grouped by kinds), so the branches on kinds are taken here, outside the lane loops;
per-lane branches of the formulas (fal's linear zone, the signs, saturation) become
selects; loops over the order ρ or the feedback length m run *outside* the lane loops, and
the transcendental functions are the branch-free ones of :mod:`aiofl.components.vecmath`
(the plant functions and the components are compiled with ``exp``, ``log``, ``sin`` and
``cos`` rebound to them).

**Numbers.**  A member's results depend only on its own data: lanes never mix, a partial
group is padded with copies of one of its members (the same code runs for every lane, so a
member's numbers are the same in any lane of any group: bitwise, checked by the tests), a
pad's results are discarded, and the kernel is compiled without fast-math flags so that the
width-1 and width-32 instances round alike (:data:`LANE_FASTMATH`).  Against the scalar
kernel the results differ by the rounding of the vector math functions and of the
fast-math flags the scalar kernel has (see ``tests/test_lanes.py`` for the metrics).

**Divergence is per lane.**  A member whose state leaves the threshold is reported as
diverged at that step (status, time, its integrals at that point, as the scalar kernel
does) and masked: its lane keeps computing but nothing of it is stored; the group stops
when every real lane has diverged or the horizon ends.

The classical IOFL law needs the plant's normal form (an array per call), which cannot be
vectorized: an IOFL group evaluates its law lane by lane with the scalar kernel's
:func:`aiofl.engine.kernel._iofl_command`; the rest of its step is vectorized.

This module's source is part of the on-disk cache fingerprint of every lane kernel.
"""

from __future__ import annotations

import numpy as np

from aiofl import layout as L
from aiofl.engine.kernel import (
    IQ_EINIT,
    IQ_ESO,
    IQ_LAW,
    IQ_M,
    IQ_NTD,
    IQ_NZ,
    IQ_OESO,
    IQ_OTD,
    IQ_RHO,
    IQ_SEF,
    IQ_TD,
    N_IQ,
    N_Q,
    N_SIG,
    Q_BETA,
    Q_LINK,
    Q_PF,
    Q_SLOPE,
    SWITCH_RTOL,
)

WIDTH = 32
"""Members per group in a batch: 32 float64 lanes, four AVX-512 registers per quantity.
Measured (20-s S1, one thread, batch 64, ``benchmarks/bench_lanes.py``'s cases): 32 lanes
run 14-28 % more member-steps per second than 16 (more independent work to hide the
latency of each formula's dependency chain), 64 lanes fewer (registers spill).  Small
batches run groups of 1 (the same code, compiled for one lane; the numbers are bitwise the
same, see lanes_build)."""

LANE_FASTMATH: set[str] = set()
"""LLVM fast-math flags of the lane kernel: none, strict IEEE 754.  With any of them
(even ``contract`` alone: ``a*b + c*d`` may fuse either product into an FMA, and LLVM's
choice differed between vector and scalar code on the dcmotor-arm plant) a member's
numbers could depend on the lane width it ran with; without them they cannot."""

# Placeholders for what a lane-kernel instance binds (see aiofl.engine.lanes_build).
_W = WIDTH
_N = 1
_N_P = 1
_NZ = 1
_PF = _PG = _PH = _PBD = _PNF = None  # the plant's functions, inlined, vector math
_SETUP = _IOFL_COMMAND = _UNMANAGED = _LEADING_ROWS = _KEEP_ALIVE = None
_REFERENCE = _DERIV = _GROUP_SETUP = None
_ASSIGN_LANES = _LOAD_LANES = _START_MEMBERS = _STOP_LANE = _FINISH_LANES = None
_STEP_INPUTS = None
# the lane blocks (see _BLOCKS)
_BLK_HAN = _BLK_ITD = _BLK_PREFILTER_START = _BLK_PREFILTER_TERM = _BLK_COPY = None
_BLK_FILL = _BLK_OUTPUT = _BLK_ERROR = _BLK_FAL = _BLK_INLSEF = _BLK_LINEAR_TERM = None
_BLK_INLSEF_LIMIT = _BLK_LINEAR_SEF = _BLK_LAW = _BLK_IOFL = _BLK_ESO_ERROR = None
_BLK_INLESO_ERROR = _BLK_ESO_ROW = _BLK_ESO_INPUT = _BLK_ESO_LAST = _BLK_PLANT = None
_BLK_DISTURBANCE = _BLK_METRICS = _BLK_RK_FIRST = _BLK_RK_MID = _BLK_RK_LAST = None
_BLK_OUT_OF_RANGE = _BLK_SINE = _BLK_SINE_DERIVATIVE = _BLK_STEP = _BLK_INPUTS = None
_HAN_TD = _ITD = _FAL = _INLSEF_TERM = _INLSEF_LIMIT = _LINEAR_SEF = None
_INLESO = _AIOFL_LAW = _SATURATE = _SIN = _COS = None

# rows of the per-lane scratch block ``s`` (see _tpl_group)
S_Y, S_YM, S_U, S_E, S_V, S_RFF, S_NOISE, S_D, S_REF, S_A, S_B, S_ERR = range(12)
N_S = 12


def _tpl_reference(t, t_hold, sc, ref_t, rrow, rr, oi, nd, kind, s):  # pragma: no cover
    """r(t) and derivatives 0..nd of every lane into ``rr[oi, k, l]`` (as
    :func:`aiofl.engine.kernel._tpl_reference`; the kind is uniform within a group)."""
    for k in range(1, nd + 1):
        _BLK_FILL(rr[oi, k], 0.0)
    if kind == L.REF_SINE:
        _BLK_SINE(
            t,
            sc[L.S_REF_A],
            sc[L.S_REF_OMEGA],
            sc[L.S_REF_PHASE],
            sc[L.S_REF_OFFSET],
            nd > 0,
            rr[oi, 0],
            s[S_A],
            s[S_B],
            s[S_ERR],
        )
        for k in range(1, nd + 1):  # d^k/dt^k sin = sin(ph + k π/2)
            _BLK_SINE_DERIVATIVE(k % 4, sc[L.S_REF_OMEGA], s[S_A], s[S_B], s[S_ERR], rr[oi, k])
    elif kind == L.REF_STEP:
        _BLK_STEP(t_hold, sc[L.S_REF_TSTEP], sc[L.S_REF_OFFSET], sc[L.S_REF_A], rr[oi, 0])
    else:
        _BLK_FILL(rr[oi, 0], 0.0)
        ns = ref_t.shape[1]
        for l in range(_W):  # samples: a table lookup per lane (not vectorized)
            dtr = sc[L.S_REF_DT, l]
            sv = t / dtr
            k0 = int(sv)
            row = rrow[l]
            if k0 >= ns - 1:
                rr[oi, 0, l] = ref_t[row, ns - 1]
            else:
                lo = ref_t[row, k0]
                hi = ref_t[row, k0 + 1]
                rr[oi, 0, l] = lo + (sv - k0) * (hi - lo)
                if nd >= 1:
                    rr[oi, 1, l] = (hi - lo) / dtr


def _tpl_deriv(t, z, dz, iq, q, p, pn, rr, ri, s, dany):  # pragma: no cover - compiled
    """F(t, z) of every lane: ``dz[:nz, l]`` and the signals in ``s`` (as
    :func:`aiofl.engine.kernel._tpl_deriv`, formula by formula, in lane blocks)."""
    rho = iq[IQ_RHO]
    m = iq[IQ_M]
    o_td = iq[IQ_OTD]
    o_eso = iq[IQ_OESO]
    td_kind = iq[IQ_TD]
    exact = td_kind == L.TD_EXACT
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

    _BLK_OUTPUT(z, p, s[S_NOISE], s[S_Y], s[S_YM])

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
                _BLK_LINEAR_TERM(q[Q_LINK + i], e, v)
        if sef_kind == L.SEF_IMPROVED:
            _BLK_INLSEF_LIMIT(q[L.F_SEF_DOUT], v)
        elif sef_kind == L.SEF_LINEAR:
            _BLK_LINEAR_SEF(q[L.F_B0], rff, v)
        _BLK_LAW(v, z[o_eso + rho], q[L.F_B0], q[L.F_UMIN], q[L.F_UMAX], u)
    else:
        _BLK_IOFL(z, iq, q, pn, rr, ri, o_td, rff, u)

    # observer, eqs. (5)/(16) or (19)
    if iq[IQ_ESO] == L.ESO_IMPROVED:
        _BLK_INLESO_ERROR(s[S_YM], z[o_eso], q[L.F_KA], q[L.F_KB], q[L.F_EA], q[L.F_EB], e)
    else:
        _BLK_ESO_ERROR(s[S_YM], z[o_eso], e)
    for i in range(rho):
        _BLK_ESO_ROW(z[o_eso + i + 1], q[Q_BETA + i], e, dz[o_eso + i])
    _BLK_ESO_INPUT(q[L.F_B0], u, dz[o_eso + rho - 1])
    _BLK_ESO_LAST(q[Q_BETA + rho], e, dz[o_eso + rho])

    dx = _LEADING_ROWS(dz, _N)
    _BLK_PLANT(z, p, u, dx)
    if dany:
        _BLK_DISTURBANCE(z, p, s[S_D], dx)
    m0 = _N
    _BLK_METRICS(t, s[S_Y], r, u, dz[m0], dz[m0 + 1], dz[m0 + 2], dz[m0 + 3], dz[m0 + 4])


def _tpl_group_setup(lanes, ints, floats, q, iq, qt):  # pragma: no cover - compiled
    """Per-lane constants ``q[:, l]`` of the group's members (kernel._tpl_setup); ``iq``
    from its first lane (kinds and sizes are uniform within a group)."""
    for l in range(_W):
        _SETUP(ints[lanes[l]], floats[lanes[l]], qt, iq)
        for i in range(N_Q):
            q[i, l] = qt[i]
    _SETUP(ints[lanes[0]], floats[lanes[0]], qt, iq)


def _tpl_assign_lanes(g, groups, lanes, real, live):  # pragma: no cover - compiled
    """Lane l runs member ``groups[g, l]``; a pad (-1) repeats the group's first member
    (``real[l]`` false, its results discarded).  Returns the number of real lanes."""
    first = groups[g, 0]
    n_real = 0
    for l in range(_W):
        mi = groups[g, l]
        real[l] = mi >= 0
        live[l] = mi >= 0
        lanes[l] = mi if mi >= 0 else first
        n_real += 1 if mi >= 0 else 0
    return n_real


def _tpl_load_lanes(  # pragma: no cover - compiled
    lanes, p_before, p_after, p_nom, scen, x0, ref_row, noise_row, pp, sc, rrow, nrow, zz
):
    """Each lane's member data into the group's columns: plant parameters (before and
    after the change, nominal, now = before: ``pp[0..3]``), scenario row, table rows and
    the initial plant state (``zz[0]`` and the stage state ``zz[1]``)."""
    for l in range(_W):
        mi = lanes[l]
        for j in range(_N_P):
            pp[0, j, l] = p_before[mi, j]
            pp[1, j, l] = p_after[mi, j]
            pp[2, j, l] = p_nom[mi, j]
            pp[3, j, l] = p_before[mi, j]
        for j in range(L.N_SCEN):
            sc[j, l] = scen[mi, j]
        rrow[l] = ref_row[mi]
        nrow[l] = noise_row[mi]
        for i in range(_N):
            zz[0, i, l] = x0[mi, i]
            zz[1, i, l] = x0[mi, i]


def _tpl_step_inputs(t, sc, noise_t, nrow, s, switched, pp):  # pragma: no cover - compiled
    """The piecewise-constant inputs of every lane at step start t, held over the step:
    measurement noise and disturbance into ``s[S_NOISE]``, ``s[S_D]``, and the plant
    parameters now (``pp[3]``) switched to the changed ones (``pp[1]``) at the lane's
    change time.  Returns whether any lane's disturbance is on."""
    _BLK_INPUTS(
        t,
        sc[L.S_NOISE_STD],
        sc[L.S_NOISE_HOLD],
        noise_t,
        nrow,
        sc[L.S_DIST_TIME],
        sc[L.S_DIST_AMP],
        s[S_NOISE],
        s[S_D],
    )
    dany = False
    for l in range(_W):
        dany = dany or s[S_D, l] != 0.0
        if not switched[l] and t >= sc[L.S_PCHANGE_TIME, l] * (1.0 - SWITCH_RTOL):
            switched[l] = True
            for j in range(_N_P):
                pp[3, j, l] = pp[1, j, l]
    return dany


def _tpl_start_members(lanes, real, status, t_div):  # pragma: no cover - compiled
    """The real lanes' members: status OK, no divergence time (yet)."""
    for l in range(_W):
        if real[l]:
            status[lanes[l]] = L.STATUS_OK
            t_div[lanes[l]] = np.nan


def _tpl_stop_lane(l, t, lanes, live, z, status, t_div, metrics):  # pragma: no cover
    """Lane l's member diverged at t: reported with its integrals so far, lane masked."""
    live[l] = False
    mi = lanes[l]
    status[mi] = L.STATUS_DIVERGED
    t_div[mi] = t
    for j in range(L.N_METRIC):
        metrics[mi, j] = z[_N + j, l]


def _tpl_finish_lanes(lanes, real, live, rows, row, z, metrics, tr, store):  # pragma: no cover
    """After the horizon: the live lanes' integrals; stored rows after each member's last
    one (its divergence) set to NaN."""
    for l in range(_W):
        if live[l]:
            mi = lanes[l]
            for j in range(L.N_METRIC):
                metrics[mi, j] = z[_N + j, l]
            rows[l] = row
    if store:
        for l in range(_W):
            if real[l]:
                mi = lanes[l]
                for rw in range(rows[l], tr.shape[1]):
                    for j in range(tr.shape[2]):
                        tr[mi, rw, j] = np.nan


def _tpl_group(  # pragma: no cover - compiled
    g,
    groups,
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
    """Integrate group ``g`` (members ``groups[g]``, -1 = pad) over the horizon, as
    :func:`aiofl.engine.kernel._tpl_member` does for one member."""
    nr = L.RHO_MAX + 2
    # lanes: member per lane (pads repeat the first member), real-lane mask
    lane_owner = np.zeros(_W, dtype=np.int64)
    real_owner = np.zeros(_W, dtype=np.bool_)
    live_owner = np.zeros(_W, dtype=np.bool_)
    rows_owner = np.zeros(_W, dtype=np.int64)
    switched_owner = np.zeros(_W, dtype=np.bool_)
    iq_owner = np.zeros(N_IQ, dtype=np.int64)
    qt_owner = np.zeros(N_Q)
    q_owner = np.zeros((N_Q, _W))
    z_owner = np.zeros((4, _NZ, _W))  # z, the stage state, F at the stage, the RK4 sum
    p_owner = np.zeros((4, _N_P, _W))  # before, after, nominal, now
    sc_owner = np.zeros((L.N_SCEN, _W))
    s_owner = np.zeros((N_S, _W))
    rr_owner = np.zeros((3, nr, _W))  # r and derivatives at t, t + dt/2, t + dt
    rrow_owner = np.zeros(_W, dtype=np.int64)
    nrow_owner = np.zeros(_W, dtype=np.int64)
    lanes = _UNMANAGED(lane_owner)
    real = _UNMANAGED(real_owner)
    live = _UNMANAGED(live_owner)
    rows = _UNMANAGED(rows_owner)
    switched = _UNMANAGED(switched_owner)
    iq = _UNMANAGED(iq_owner)
    qt = _UNMANAGED(qt_owner)
    q = _UNMANAGED(q_owner)
    zz = _UNMANAGED(z_owner)
    pp = _UNMANAGED(p_owner)
    sc = _UNMANAGED(sc_owner)
    s = _UNMANAGED(s_owner)
    rrs = _UNMANAGED(rr_owner)
    rrow = _UNMANAGED(rrow_owner)
    nrow = _UNMANAGED(nrow_owner)
    ref_t = _UNMANAGED(ref_table)
    noise_t = _UNMANAGED(noise_table)
    tr = _UNMANAGED(traj)
    z = zz[0]
    zt = zz[1]
    kd = zz[2]
    acc = zz[3]
    pn = pp[2]
    p = pp[3]
    n_live = _ASSIGN_LANES(g, groups, lanes, real, live)
    _GROUP_SETUP(lanes, ints, floats, q, iq, qt)
    rho = iq[IQ_RHO]
    nza = iq[IQ_NZ]
    o_td = iq[IQ_OTD]
    o_eso = iq[IQ_OESO]
    ntd = iq[IQ_NTD]
    exact = iq[IQ_TD] == L.TD_EXACT
    nd = rho if exact else 0
    init_output = iq[IQ_EINIT] == L.ESO_INIT_OUTPUT
    _LOAD_LANES(
        lanes, p_before, p_after, p_nom, scen, x0, ref_row, noise_row, pp, sc, rrow, nrow, zz
    )
    _START_MEMBERS(lanes, real, status, t_div)
    ref_kind = int(sc[L.S_REF_KIND, 0])  # uniform within a group
    n_stages = 4 if method == L.METHOD_RK4 else 1
    hdt = 0.5 * dt
    sixth = dt / 6.0
    row = 0
    save_in = 0
    step_ref = ref_kind == L.REF_STEP
    for k in range(n_steps + 1):
        t = k * dt
        if k == 0 or n_stages == 1 or step_ref:
            _REFERENCE(t, t, sc, ref_t, rrow, rrs, 0, nd, ref_kind, s)
        dany = _STEP_INPUTS(t, sc, noise_t, nrow, s, switched, pp)
        if k == 0 and init_output:
            # ξ̂_1(0) = y_meas(0) = h(x(0)) + n(0), the first measurement; ξ̂_2.. stay 0
            for l in range(_W):
                z[o_eso, l] = _PH(z[:, l], p[:, l]) + s[S_NOISE, l]
                zt[o_eso, l] = z[o_eso, l]
        for st in range(n_stages):
            if st == 0:
                ts = t
                ri = 0
            elif st == 3:
                ts = (k + 1) * dt
                ri = 2
            else:
                ts = (k + 0.5) * dt
                ri = 1
                if st == 1:
                    _REFERENCE(ts, t, sc, ref_t, rrow, rrs, 1, nd, ref_kind, s)
                    _REFERENCE((k + 1) * dt, t, sc, ref_t, rrow, rrs, 2, nd, ref_kind, s)
            _DERIV(ts, zt, kd, iq, q, p, pn, rrs, ri, s, dany)
            if st == 0:
                if store and save_in == 0:
                    for l in range(_W):
                        if not live[l]:
                            continue
                        mi = lanes[l]
                        tr[mi, row, 0] = t
                        tr[mi, row, 1] = rrs[0, 0, l]
                        tr[mi, row, 2] = s[S_Y, l]
                        tr[mi, row, 3] = s[S_YM, l]
                        tr[mi, row, 4] = s[S_U, l]
                        tr[mi, row, 5] = s[S_D, l]
                        for j in range(_N):
                            tr[mi, row, N_SIG + j] = z[j, l]
                        c0 = N_SIG + _N
                        for j in range(L.RHO_MAX + 1):
                            tr[mi, row, c0 + j] = z[o_eso + j, l] if j <= rho else 0.0
                        c0 += L.RHO_MAX + 1
                        for j in range(L.RHO_MAX):
                            val = 0.0
                            if exact and j < rho:
                                val = rrs[0, j, l]
                            elif j < ntd:
                                val = z[o_td + j, l]
                            tr[mi, row, c0 + j] = val
                        rows[l] = row + 1
                    row += 1
                    save_in = decimation
                save_in -= 1
                if k == n_steps:
                    break
                if n_stages == 1:  # forward Euler
                    _BLK_RK_FIRST(z, zt, kd, acc, nza, dt, True)
                else:
                    _BLK_RK_FIRST(z, zt, kd, acc, nza, hdt, False)
            elif st == 1:
                _BLK_RK_MID(z, zt, kd, acc, nza, hdt)
            elif st == 2:
                _BLK_RK_MID(z, zt, kd, acc, nza, dt)
            else:
                _BLK_RK_LAST(z, zt, kd, acc, nza, sixth)
                for j in range(nd + 1):
                    _BLK_COPY(rrs[2, j], rrs[0, j])
        if k == n_steps:
            break
        # divergence, lane by lane: |z| < threshold fails (also for NaN)
        _BLK_OUT_OF_RANGE(z, nza, threshold, s[S_ERR])
        for l in range(_W):
            if live[l] and s[S_ERR, l] != 0.0:
                _STOP_LANE(l, (k + 1) * dt, lanes, live, z, status, t_div, metrics)
                n_live -= 1
        if n_live == 0:
            break
    _FINISH_LANES(lanes, real, live, rows, row, z, metrics, tr, store)
    _KEEP_ALIVE(lane_owner, real_owner, live_owner, rows_owner, switched_owner, iq_owner)
    _KEEP_ALIVE(qt_owner, q_owner, z_owner, p_owner, sc_owner, s_owner)
    _KEEP_ALIVE(rr_owner, rrow_owner, nrow_owner, nrow_owner, nrow_owner, nrow_owner)


def _tpl_keep_alive(a, b, c, d, e, f):  # pragma: no cover - compiled
    """A use of the arrays that own the memory of unmanaged views, so they live until here."""
    return a.size + b.size + c.size + d.size + e.size + f.size
