r"""The sampled-data closed loop in SIMD lanes: a group of sampled members advanced together.

The lane counterpart of :func:`aiofl.engine.sampled._tpl_member_sampled`, whose semantics it
follows step for step (ADC, controller, DAC at :math:`t_k = kT_s`, the plant and the
performance integrals by RK4 or Euler at ``dt`` in between, see
:mod:`aiofl.engine.discrete`).  The members of a group share their component kinds, their
reference kind and their sample period in steps N (:func:`aiofl.engine.lanes_build.plan_groups`
groups them so), so every lane samples at the same steps; their sample times, delays,
quanta and coefficients may differ.

**What runs in lanes.**  Between samples the work is the plant's: its f, g, h and b_d, the
integrands of eq. (22) and the RK stages, applied to every lane by the lane blocks of the
continuous kernel (:mod:`aiofl.engine.lane_blocks`), the state as a (rows, W) array.  The
controller runs once every N steps, lane by lane, as one scalar call of the sampled
kernel's own update (:func:`aiofl.engine.sampled._tpl_ctrl_step`, or the IOFL law), on the
member's row of a lane-major controller state (``cs[l]``): at N = 10 (1 kHz at
dt = 1e-4) it is one call per 40 plant evaluations.  Compiled with the lane kernel's strict
arithmetic and vector math (:mod:`aiofl.engine.lanes_build`), a member's numbers are the
same, bit for bit, in any lane of a group of any width, as for the continuous members.

This module's source is part of the on-disk cache fingerprint of every lane kernel.
"""

from __future__ import annotations

import numpy as np

from aiofl import layout as L
from aiofl.engine.discrete import D_DELAY, D_STEPS, D_UQ, D_YQ, N_DISC
from aiofl.engine.kernel import (
    IQ_LAW,
    IQ_NTD,
    IQ_RHO,
    IQ_TD,
    N_IQ,
    N_Q,
    N_SIG,
)
from aiofl.engine.lanes import N_S, S_D, S_ERR, S_NOISE, S_U, S_Y
from aiofl.engine.sampled import C_P, C_PROF, C_TD, C_UPREV, C_X, N_CS

# Placeholders for what a lane-kernel instance binds (see aiofl.engine.lanes_build).
_W = 32
_N = 1
_N_P = 1
_PNF = _SETUP = _IOFL_COMMAND = _SATURATE = _UNMANAGED = _LEADING_ROWS = None
_KEEP_ALIVE = _REFERENCE = _CTRL_INIT = _CTRL_STEP = _PLANT_DERIV = None
_ASSIGN_LANES = _LOAD_LANES = _START_MEMBERS = _STOP_LANE = _FINISH_LANES = None
_STEP_INPUTS = None
_BLK_OUTPUT = _BLK_PLANT = _BLK_DISTURBANCE = _BLK_METRICS = _BLK_INPUTS = None
_BLK_RK_FIRST = _BLK_RK_MID = _BLK_RK_LAST = _BLK_OUT_OF_RANGE = _BLK_COPY = None


def _tpl_plant_deriv(t, z, dz, p, s, r, dany):  # pragma: no cover - compiled
    """The plant under the held command ``s[S_U]`` and the integrands of eq. (22), every
    lane (:func:`aiofl.engine.sampled._tpl_plant_deriv`); y into ``s[S_Y]``."""
    _BLK_OUTPUT(z, p, s[S_NOISE], s[S_Y], s[S_ERR])  # (the noisy copy is not used here)
    dx = _LEADING_ROWS(dz, _N)
    _BLK_PLANT(z, p, s[S_U], dx)
    if dany:
        _BLK_DISTURBANCE(z, p, s[S_D], dx)
    m0 = _N
    _BLK_METRICS(t, s[S_Y], r, s[S_U], dz[m0], dz[m0 + 1], dz[m0 + 2], dz[m0 + 3], dz[m0 + 4])


def _tpl_group_sampled(  # pragma: no cover - compiled
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
    disc,
):
    """Integrate the sampled group ``g`` (members ``groups[g]``, -1 = pad) over the
    horizon, as :func:`aiofl.engine.sampled._tpl_member_sampled` does for one member."""
    nr = L.RHO_MAX + 2
    nza = _N + L.N_METRIC
    lane_owner = np.zeros(_W, dtype=np.int64)
    real_owner = np.zeros(_W, dtype=np.bool_)
    live_owner = np.zeros(_W, dtype=np.bool_)
    rows_owner = np.zeros(_W, dtype=np.int64)
    switched_owner = np.zeros(_W, dtype=np.bool_)
    iq_owner = np.zeros(N_IQ, dtype=np.int64)
    q_owner = np.zeros((_W, N_Q))  # controller data lane-major: one row per member
    dsc_owner = np.zeros((_W, N_DISC))
    cs_owner = np.zeros((_W, N_CS))
    scr_owner = np.zeros((_W, N_CS))
    rl_owner = np.zeros((1, nr))  # one lane's reference and derivatives at t_k
    ym_owner = np.zeros(_W)  # the last sample's measurement
    z_owner = np.zeros((4, nza, _W))  # z, the stage state, F at the stage, the RK4 sum
    p_owner = np.zeros((4, _N_P, _W))  # before, after, nominal, now
    sc_owner = np.zeros((L.N_SCEN, _W))
    s_owner = np.zeros((N_S, _W))
    rr_owner = np.zeros((4, nr, _W))  # r at t, t + dt/2, t + dt; r and derivatives at t_k
    rrow_owner = np.zeros(_W, dtype=np.int64)
    nrow_owner = np.zeros(_W, dtype=np.int64)
    lanes = _UNMANAGED(lane_owner)
    real = _UNMANAGED(real_owner)
    live = _UNMANAGED(live_owner)
    rows = _UNMANAGED(rows_owner)
    switched = _UNMANAGED(switched_owner)
    iq = _UNMANAGED(iq_owner)
    q = _UNMANAGED(q_owner)
    dsc = _UNMANAGED(dsc_owner)
    cs = _UNMANAGED(cs_owner)
    scr = _UNMANAGED(scr_owner)
    rl = _UNMANAGED(rl_owner)
    ym = _UNMANAGED(ym_owner)
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
    for l in range(_W):
        mi = lanes[l]
        _SETUP(ints[mi], floats[mi], q[l], iq)
        for j in range(N_DISC):
            dsc[l, j] = disc[mi, j]
    _LOAD_LANES(
        lanes, p_before, p_after, p_nom, scen, x0, ref_row, noise_row, pp, sc, rrow, nrow, zz
    )
    _START_MEMBERS(lanes, real, status, t_div)
    _SETUP(ints[lanes[0]], floats[lanes[0]], q[0], iq)  # kinds: uniform within a group
    n_per = int(dsc[0, D_STEPS])  # uniform within a group
    rho = iq[IQ_RHO]
    ntd = iq[IQ_NTD]
    exact = iq[IQ_TD] == L.TD_EXACT
    iofl = iq[IQ_LAW] == L.LAW_IOFL
    nd = rho if exact else 0
    ref_kind = int(sc[L.S_REF_KIND, 0])
    step_ref = ref_kind == L.REF_STEP
    rk4 = method == L.METHOD_RK4
    hdt = 0.5 * dt
    sixth = dt / 6.0
    row = 0
    save_in = 0
    for l in range(_W):
        s[S_U, l] = 0.0  # the command the plant gets over the current sample interval
    for k in range(n_steps + 1):
        t = k * dt
        dany = _STEP_INPUTS(t, sc, noise_t, nrow, s, switched, pp)
        if k % n_per == 0 and k < n_steps:  # a sample: ADC, controller, DAC, lane by lane
            _BLK_OUTPUT(z, p, s[S_NOISE], s[S_Y], ym)
            _REFERENCE(t, t, sc, ref_t, rrow, rrs, 3, nd, ref_kind, s)
            for l in range(_W):
                yq = dsc[l, D_YQ]
                yl = yq * np.floor(ym[l] / yq + 0.5) if yq > 0.0 else ym[l]
                ym[l] = yl
                for j in range(nr):
                    rl[0, j] = rrs[3, j, l]
                if k == 0:
                    _CTRL_INIT(iq, cs[l], yl)
                u_before = cs[l, C_UPREV]
                if iofl:  # classical IOFL from the true state and the nominal model
                    nfx = _PNF(z[:_N, l].copy(), pn[:, l].copy())
                    uc = _IOFL_COMMAND(iq, q[l], rl, 0, cs[l], C_PROF, nfx, rl[0, rho])
                    uc = _SATURATE(uc, q[l, L.F_UMIN], q[l, L.F_UMAX])
                    cs[l, C_UPREV] = uc
                else:
                    uc = _CTRL_STEP(iq, q[l], dsc[l], cs[l], scr[l], yl, rl, 0)
                ua = u_before if dsc[l, D_DELAY] > 0.0 else uc
                uq = dsc[l, D_UQ]
                s[S_U, l] = uq * np.floor(ua / uq + 0.5) if uq > 0.0 else ua
        if k == 0 or not rk4 or step_ref:  # else r(t) is the last step's r(t + dt)
            _REFERENCE(t, t, sc, ref_t, rrow, rrs, 0, 0, ref_kind, s)
        if rk4:
            _REFERENCE((k + 0.5) * dt, t, sc, ref_t, rrow, rrs, 1, 0, ref_kind, s)
            _REFERENCE((k + 1) * dt, t, sc, ref_t, rrow, rrs, 2, 0, ref_kind, s)
        _PLANT_DERIV(t, zt, kd, p, s, rrs[0, 0], dany)
        if store and save_in == 0:
            for l in range(_W):
                if not live[l]:
                    continue
                mi = lanes[l]
                tr[mi, row, 0] = t
                tr[mi, row, 1] = rrs[0, 0, l]
                tr[mi, row, 2] = s[S_Y, l]
                tr[mi, row, 3] = ym[l]
                tr[mi, row, 4] = s[S_U, l]
                tr[mi, row, 5] = s[S_D, l]
                for j in range(_N):
                    tr[mi, row, N_SIG + j] = z[j, l]
                c0 = N_SIG + _N
                for j in range(L.RHO_MAX + 1):
                    tr[mi, row, c0 + j] = cs[l, C_X + j] if j <= rho and not iofl else 0.0
                c0 += L.RHO_MAX + 1
                for j in range(L.RHO_MAX):
                    val = 0.0
                    if exact and j < rho:
                        val = rrs[3, j, l]
                    elif j < ntd:
                        val = cs[l, C_PROF + j]  # the profile the last sample used
                    tr[mi, row, c0 + j] = val
                rows[l] = row + 1
            row += 1
            save_in = decimation
        save_in -= 1
        if k == n_steps:
            break
        if not rk4:  # forward Euler
            _BLK_RK_FIRST(z, zt, kd, acc, nza, dt, True)
        else:
            _BLK_RK_FIRST(z, zt, kd, acc, nza, hdt, False)
            _PLANT_DERIV((k + 0.5) * dt, zt, kd, p, s, rrs[1, 0], dany)
            _BLK_RK_MID(z, zt, kd, acc, nza, hdt)
            _PLANT_DERIV((k + 0.5) * dt, zt, kd, p, s, rrs[1, 0], dany)
            _BLK_RK_MID(z, zt, kd, acc, nza, dt)
            _PLANT_DERIV((k + 1) * dt, zt, kd, p, s, rrs[2, 0], dany)
            _BLK_RK_LAST(z, zt, kd, acc, nza, sixth)
            _BLK_COPY(rrs[2, 0], rrs[0, 0])
        # divergence, lane by lane: the command, the plant, the ESO prediction, the TD
        _BLK_OUT_OF_RANGE(z, nza, threshold, s[S_ERR])
        for l in range(_W):
            bad = s[S_ERR, l] != 0.0 or not abs(s[S_U, l]) < threshold
            for j in range(C_P, C_P + rho + 1):  # (the first is p_1 - y)
                bad = bad or not abs(cs[l, j]) < threshold
            for j in range(ntd):
                bad = bad or not abs(cs[l, C_TD + j]) < threshold
            if live[l] and bad:
                _STOP_LANE(l, (k + 1) * dt, lanes, live, z, status, t_div, metrics)
                n_live -= 1
        if n_live == 0:
            break
    _FINISH_LANES(lanes, real, live, rows, row, z, metrics, tr, store)
    _KEEP_ALIVE(lane_owner, real_owner, live_owner, rows_owner, switched_owner, iq_owner)
    _KEEP_ALIVE(q_owner, dsc_owner, cs_owner, scr_owner, rl_owner, ym_owner)
    _KEEP_ALIVE(z_owner, p_owner, sc_owner, s_owner, rr_owner, rrow_owner)
    _KEEP_ALIVE(nrow_owner, nrow_owner, nrow_owner, nrow_owner, nrow_owner, nrow_owner)
