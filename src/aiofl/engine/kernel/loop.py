r"""The time loop: one template that every engine instance is compiled from.

:func:`_tpl_loop` integrates a *group* of members over the horizon, one member per lane of
the (rows, W) workspace arrays (:mod:`aiofl.engine.kernel.lane_blocks` holds the formulas, each a
loop over the lanes that LLVM vectorizes).  It owns everything that is not the controller:
the workspace, the lanes' members, the piecewise-constant inputs held over each step
(measurement noise, disturbance, plant-parameter change), the reference and its
derivatives at the stage times, the integration method, the trajectory store, divergence
and the finish.  The controller plugs in:

- **continuous** (``_SAMPLED`` false): its blocks are part of the stage right-hand side
  ``_RHS`` (:func:`aiofl.engine.kernel.continuous._tpl_deriv`: TD, SEF, law, ESO, plant and the
  integrands of eq. 22, one ODE);
- **sampled** (``_SAMPLED`` true): ``_RHS`` is the plant and the integrands under the held
  command (:func:`aiofl.engine.kernel.sampled._tpl_plant_deriv`), and every N steps, at
  :math:`t_k = kT_s`, ``_SAMPLE`` runs the discrete controller lane by lane (ADC, update,
  DAC; :func:`aiofl.engine.kernel.sampled._tpl_sample`).

The lane width ``_W`` (32, or 1 for a lone member) and the timing ``_SAMPLED`` are
compile-time constants of an instance (:mod:`aiofl.engine.build.instances`), so the compiled code
carries no branch of the other timing.  The integration method is data: a stage table
(:data:`STAGE_TIME`, :data:`STAGE_NEXT`, :data:`STAGE_WEIGHT`, :data:`STAGE_DIVISOR`) drives
one stage routine (``_BLK_STAGE``) for RK4 and forward Euler alike.

**Semantics** (every instance).  The plant starts at the scenario's x0, the differentiator
at 0, the ESO at 0 or (``eso.init = "output"``) with :math:`\hat\xi_1(0) = y_m(0)`
(``"bumpless"``: and the differentiator's :math:`r_1(0) = y_m(0)`).
Piecewise-constant inputs take their value at the start of a step for all its stages, so
the integrator never straddles a jump: a switch on the time grid is exact, one between grid
points acts from the next step (:data:`aiofl.engine.kernel.member.SWITCH_RTOL`).  At every step
the plant is watched (:func:`_tpl_watch`): a member whose output leaves its envelope
around the reference, or whose output or a state leaves its declared range, is *lost* at
that step; one whose plant state leaves ``|x| < threshold`` or whose integrals or
controller states (the ESO, the differentiator, sampled: the command and the ESO's
prediction) stop being finite is *diverged* (numerical blow-up).  The observer's states
never make a member lost.  Either way it is reported with its time and its integrals and
statistics so far, and its lane is masked; the group stops when no real lane is live.  A
partial group is padded with copies of its first member, whose results are discarded.
Trajectories are stored every ``decimation``-th step when asked for.

**Numbers.**  A member's results depend only on its own data: lanes never mix, and the lane
instances are compiled with strict IEEE arithmetic (:data:`LANE_FASTMATH`), so a member's
numbers are the same, bit for bit, in any lane of a group of any width.

This module's source is part of the cache fingerprint of every kernel.
"""

from __future__ import annotations

import numpy as np

from aiofl import layout as L
from aiofl.engine.kernel.member import (
    IQ_EINIT,
    IQ_NTD,
    IQ_NZ,
    IQ_OESO,
    IQ_OTD,
    IQ_RHO,
    IQ_TD,
    N_IQ,
    N_Q,
    N_SIG,
    SWITCH_RTOL,
)

WIDTH = 32
"""Members per group in a batch: 32 float64 lanes, four AVX-512 registers per quantity (more
independent work to hide each formula's dependency chain than 16; 64 spill registers; see
``docs/benchmarks.md``).  Small batches run groups of 1 (the same code, compiled for one
lane; the numbers are bitwise the same, see :mod:`aiofl.engine.build.instances`)."""

LANE_FASTMATH: set[str] = set()
"""LLVM fast-math flags of the lane instances: none, strict IEEE 754.  With any of them
(even ``contract`` alone: ``a*b + c*d`` may fuse either product into an FMA, and LLVM's
choice differed between vector and scalar code on the dcmotor-arm plant) a member's
numbers could depend on the lane width it ran with; without them they cannot."""

# ------------------------------------------------------------------- the stage tables
# Method m has STAGE_COUNT[m] stages; stage s is evaluated at t_k + STAGE_TIME[m, s] dt (its
# reference slot is 2 STAGE_TIME); after it, the next stage's state is z + STAGE_NEXT[m, s]
# dt k_s and the weighted sum gains STAGE_WEIGHT[m, s] k_s; after the last stage
# z += dt / STAGE_DIVISOR[m] (sum).  Rows: METHOD_RK4 (classical RK4), METHOD_EULER.
STAGE_COUNT = np.array([4, 1], dtype=np.int64)
STAGE_TIME = np.array([[0.0, 0.5, 0.5, 1.0], [0.0, 0.0, 0.0, 0.0]])
STAGE_NEXT = np.array([[0.5, 0.5, 1.0, 0.0], [0.0, 0.0, 0.0, 0.0]])
STAGE_WEIGHT = np.array([[1.0, 2.0, 2.0, 1.0], [1.0, 0.0, 0.0, 0.0]])
STAGE_DIVISOR = np.array([6.0, 1.0])

# rows of the per-lane signal block ``s`` (one value per lane each)
S_Y = 0  #: plant output y = h(x)
S_YM = 1  #: measured output y + noise (continuous); sampled: the last sample's measurement
S_U = 2  #: command (continuous: at the stage; sampled: held over the sample interval)
S_E = 3  #: observer innovation / SEF error scratch
S_V = 4  #: the SEF's virtual control v
S_RFF = 5  #: the reference feed-forward r^(ρ) (or the prefilter's last derivative)
S_NOISE = 6  #: measurement noise, held over the step
S_D = 7  #: input disturbance, held over the step
S_SIN = 8  #: sin of the reference's phase (for its derivatives)
S_COS = 9  #: cos of the reference's phase
S_AMP = 10  #: amplitude times ω^k of the reference's k-th derivative
S_BAD = 11  #: the number of the lane's states out of range (divergence)
S_AHAT = 12  #: model-assisted observer: the nominal α at x̂ = Φ⁻¹(ξ̂)
S_BHAT = 13  #: model-assisted observer: the nominal β at x̂
S_UC = 14  #: input delay: the controller's command (S_U is the delayed one, the plant's)
S_YD = 15  #: output delay: y(t - τ_out), what the ADC (sampled) or the ESO reads (plus noise)
S_YDON = 16  #: 1 in a lane with an output delay, else 0
S_YS = 17  #: sampled: y + noise at this step, what a lane due to sample reads
S_UREF = 18  #: the command ISU and IAU are measured about (scenario.u_ref)
S_LOST = 19  #: 1 when the lane's plant left its envelope at this step (_tpl_watch)
S_UD = 20  #: continuous, input delay: the command of this stage m steps back
S_UDON = 21  #: continuous: 1 in a lane with an input delay, else 0
N_S = 22

# Placeholders: stand-ins so this module imports.  Every instance's namespace is filled by
# aiofl/engine/build/instances.py:recipe: the sizes and the timing by its ``ns.update``, the
# others by its ``templates`` (each compiled under the name it is called by here); a name an
# instance does not use keeps its stand-in (a continuous instance's _SAMPLE ..., in branches
# on _SAMPLED that numba prunes).
_W = WIDTH  # lane width: 32, or 1 for a lone member
_SAMPLED = False  # the timing: continuous (False) or sampled (True)
_N = 1  # the plant's number of states
_NZ = 1  # the integrated state's rows (plant, integrals, and continuous: TD and ESO)
_CONTROLLER_SIZE = 1  # row length of the discrete controller's state (sampled instances)
_PH = None  # the plant's h (kernel.plant_calls, via build/plant_table.py)
_UNMANAGED = None  # kernel.views.unmanaged_intrinsic()
# templates of this module (_tpl_keep_alive, _tpl_assign_lanes, ..., _tpl_delay_setup)
_KEEP_ALIVE = _STORE_ROW = _REFERENCE = _STEP_INPUTS = _DELAY_SETUP = None
_ASSIGN_LANES = _LOAD_LANES = _START_MEMBERS = _STOP_LANE = _FINISH_LANES = _WATCH = None
# the controller's plug-in: kernel.continuous._tpl_setup/_tpl_deriv/... or
# kernel.sampled._tpl_setup/_tpl_plant_deriv/_tpl_sample/...
_RHS = _SETUP = _SAMPLE = _CONTROLLER_BAD = _STORE_CONTROLLER = None
_DELAY_OUTPUT = _DELAY_INPUT = _DELAY_STAGE_IN = _DELAY_STAGE_OUT = None
# lane blocks (kernel.lane_blocks._blk_stage ... under their upper-case names)
_BLK_STAGE = _BLK_OUT_OF_RANGE = _BLK_COPY = _BLK_FILL = _BLK_INPUTS = None
_BLK_SINE = _BLK_SINE_DERIVATIVE = _BLK_STEP = None
PLACEHOLDERS = tuple(
    """
    _W _SAMPLED _N _NZ _CONTROLLER_SIZE _PH _UNMANAGED _KEEP_ALIVE _STORE_ROW _REFERENCE
    _STEP_INPUTS _DELAY_SETUP _ASSIGN_LANES _LOAD_LANES _START_MEMBERS _STOP_LANE
    _FINISH_LANES _WATCH _RHS _SETUP _SAMPLE _CONTROLLER_BAD _STORE_CONTROLLER _DELAY_OUTPUT
    _DELAY_INPUT _DELAY_STAGE_IN _DELAY_STAGE_OUT _BLK_STAGE _BLK_OUT_OF_RANGE _BLK_COPY
    _BLK_FILL _BLK_INPUTS _BLK_SINE _BLK_SINE_DERIVATIVE _BLK_STEP
    """.split()  # noqa: SIM905 - the names as a reader scans them
)
"""The names of the placeholder block: what the compile factory checks a recipe binds
when a template of this module reads one (:func:`aiofl.engine.build.compile.build`)."""


def _tpl_delay_setup(sc, dt, dsteps, s):  # pragma: no cover - compiled
    r"""The lanes' transport delays in steps, :math:`m = \tau/dt` (``dsteps[0]``: input,
    ``[1]``: output; checked on the host to be integers,
    :func:`aiofl.engine.discrete_rows.delay_steps`), the lanes' output-delay flags
    ``s[S_YDON]``; returns the largest."""
    most = 0
    for l in range(_W):
        for j in range(2):
            m = int(np.floor(sc[L.S_IN_DELAY + j, l] / dt + 0.5))
            dsteps[j, l] = m
            most = max(most, m)
        s[S_YDON, l] = 1.0 if dsteps[1, l] > 0 else 0.0
    return most


def _tpl_loop(g, groups, batch, out):  # pragma: no cover - compiled
    """Integrate group ``g`` (members ``groups[g]``, -1 = pad) over the horizon: ``batch``
    is a :class:`aiofl.engine.batch.Batch`, ``out`` an :class:`aiofl.engine.batch.Outputs`."""
    nr = L.RHO_MAX + 2
    nsw = _W if _SAMPLED else 1  # lanes of the discrete controller's state
    lane_owner = np.zeros(_W, dtype=np.int64)  # the member of each lane
    real_owner = np.zeros(_W, dtype=np.bool_)  # a real member (not a pad)
    live_owner = np.zeros(_W, dtype=np.bool_)  # real and not diverged
    rows_owner = np.zeros(_W, dtype=np.int64)  # trajectory rows stored per lane
    switched_owner = np.zeros(_W, dtype=np.bool_)  # plant parameters changed
    iq_owner = np.zeros(N_IQ, dtype=np.int64)  # kinds and offsets (uniform in a group)
    # the per-member constants: rows x lanes (continuous: read by lane blocks), or one row
    # per lane (sampled: read by the scalar controller update)
    q_owner = np.zeros((_W, N_Q)) if _SAMPLED else np.zeros((N_Q, _W))
    qt_owner = np.zeros(N_Q)  # one member's constants, before they are spread
    ctrl_owner = np.zeros((3, nsw, _CONTROLLER_SIZE))  # sampled: coefficients, state, scratch
    rl_owner = np.zeros((1, nr))  # sampled: one lane's reference and derivatives at t_k
    z_owner = np.zeros((4, _NZ, _W))  # z, the stage state, F at the stage, the weighted sum
    n_p = batch.p_before.shape[1]  # the plant's parameters (read at run time)
    p_owner = np.zeros((4, n_p, _W))  # parameters before, after, nominal, now
    sc_owner = np.zeros((L.N_SCEN, _W))
    s_owner = np.zeros((N_S, _W))
    # r and derivatives at t, t + dt/2, t + dt; sampled: at a lane's last sample t_k, at t
    rr_owner = np.zeros((5, nr, _W))
    rrow_owner = np.zeros(_W, dtype=np.int64)
    nrow_owner = np.zeros(_W, dtype=np.int64)
    # sampled: each lane's steps per sample, the step of its next sample, due at this step
    nper_owner = np.zeros(_W, dtype=np.int64)
    next_owner = np.zeros(_W, dtype=np.int64)
    due_owner = np.zeros(_W, dtype=np.bool_)
    lanes = _UNMANAGED(lane_owner)
    real = _UNMANAGED(real_owner)
    live = _UNMANAGED(live_owner)
    rows = _UNMANAGED(rows_owner)
    switched = _UNMANAGED(switched_owner)
    iq = _UNMANAGED(iq_owner)
    q = _UNMANAGED(q_owner)
    qt = _UNMANAGED(qt_owner)
    ctrl = _UNMANAGED(ctrl_owner)
    rl = _UNMANAGED(rl_owner)
    zz = _UNMANAGED(z_owner)
    pp = _UNMANAGED(p_owner)
    sc = _UNMANAGED(sc_owner)
    s = _UNMANAGED(s_owner)
    rrs = _UNMANAGED(rr_owner)
    rrow = _UNMANAGED(rrow_owner)
    nrow = _UNMANAGED(nrow_owner)
    nper = _UNMANAGED(nper_owner)
    next_sample = _UNMANAGED(next_owner)
    due = _UNMANAGED(due_owner)
    ref_t = _UNMANAGED(batch.ref_table)
    noise_t = _UNMANAGED(batch.noise_table)
    tr = _UNMANAGED(out.traj)
    z = zz[0]
    zt = zz[1]
    kd = zz[2]
    acc = zz[3]
    pn = pp[2]
    p = pp[3]
    fns = batch.plant_table  # the plant's functions (plant-independent instances)
    dt = batch.dt
    n_steps = batch.n_steps
    threshold = batch.threshold
    store = batch.store
    decimation = batch.decimation

    n_live = _ASSIGN_LANES(g, groups, lanes, real, live)
    _SETUP(lanes, batch, q, qt, iq, ctrl, nper)
    _LOAD_LANES(lanes, batch, pp, sc, rrow, nrow, zz)
    _START_MEMBERS(lanes, real, out)
    # what the loop watches per lane (aiofl.layout ST_*): peaks, saturation, step response,
    # the steady-state window; the first-crossing times start undefined (NaN)
    st_owner = np.zeros((L.N_STAT, _W))
    stv = _UNMANAGED(st_owner)
    alone = np.zeros(_W, dtype=np.bool_)  # one lane's mask, to store its last point
    for l in range(_W):
        s[S_UREF, l] = sc[L.S_U_REF, l]
        stv[L.ST_STEP_PEAK, l] = -np.inf
        stv[L.ST_T10, l] = np.nan
        stv[L.ST_T90, l] = np.nan
        stv[L.ST_T_OUT, l] = np.nan
    # transport delays: ring buffers of the held commands and of y per step (sampled), of
    # the controller's command and y at every stage of a step (continuous), per lane
    dsteps = np.zeros((2, _W), dtype=np.int64)  # input, output delay in steps
    nbuf = _DELAY_SETUP(sc, dt, dsteps, s) + 1
    delayed = nbuf > 1
    n_ring = 1 if _SAMPLED else STAGE_COUNT[batch.method]
    ring = np.zeros((2, nbuf * n_ring, _W))  # [0]: held command per step, [1]: y
    if delayed and not _SAMPLED:  # y(0), what the observer reads while t < τ_out
        _DELAY_STAGE_OUT(0, 0, 1, s, ring, fns, z, p)
    rho = iq[IQ_RHO]
    nza = _N + L.N_METRIC if _SAMPLED else iq[IQ_NZ]
    nd = rho if iq[IQ_TD] == L.TD_EXACT else 0
    nd_stage = 0 if _SAMPLED else nd  # derivatives the right-hand side reads
    init_output = iq[IQ_EINIT] != L.ESO_INIT_ZERO  # "output" or "bumpless"
    init_td = iq[IQ_EINIT] == L.ESO_INIT_BUMPLESS and iq[IQ_NTD] > 0
    ref_kind = int(sc[L.S_REF_KIND, 0])  # uniform within a group
    hold_ref = ref_kind == L.REF_STEP  # a step reference is held over the step
    method = batch.method
    n_stages = STAGE_COUNT[method]
    scale = dt / STAGE_DIVISOR[method]
    row = 0
    save_in = 0
    next_any = 0  # sampled: the step of the group's next sample (its lanes' earliest)
    for k in range(n_steps + 1):
        t = k * dt
        # r(t): carried over from the last step's t + dt unless held or first (RK4)
        if k == 0 or n_stages == 1 or hold_ref:
            _REFERENCE(t, t, sc, ref_t, rrow, rrs, 0, nd_stage, ref_kind, s)
        if n_stages > 1:
            _REFERENCE((k + 0.5) * dt, t, sc, ref_t, rrow, rrs, 1, nd_stage, ref_kind, s)
            _REFERENCE((k + 1) * dt, t, sc, ref_t, rrow, rrs, 2, nd_stage, ref_kind, s)
        dany = _STEP_INPUTS(t, sc, noise_t, nrow, s, switched, pp)
        if _SAMPLED:
            # a sample of the lanes due (each at its own period: k a multiple of nper[l])
            sample = k == next_any and k < n_steps
            if sample:
                next_any = n_steps
                for l in range(_W):
                    d = next_sample[l] == k
                    due[l] = d
                    next_sample[l] += nper[l] if d else 0
                    next_any = min(next_any, next_sample[l])
            if delayed:  # y(t_k) into the ring, y(t_k - τ_out) into s[S_YD]
                _DELAY_OUTPUT(fns, k, z, p, s, ring, dsteps)
            if sample:  # a sample of the lanes due: ADC, controller, DAC
                _REFERENCE(t, t, sc, ref_t, rrow, rrs, 4, nd, ref_kind, s)
                _SAMPLE(fns, k, z, p, pn, s, rrs, rl, iq, q, ctrl, due)
            if delayed:  # the plant's command u(t_k - τ_in) into s[S_U]
                _DELAY_INPUT(k, due, s, ring, dsteps)
            if sample:  # no lane is due until the next sample
                for l in range(_W):
                    due[l] = False
        elif k == 0 and init_output:
            # ξ̂_1(0) = y_meas(0) = h(x(0)) + n(0), the first measurement; ξ̂_2.. stay 0;
            # bumpless: the differentiator's r_1(0) too (at rest at y_meas(0))
            # and ξ̂_{ρ+1}(0) = -b0 u0, the holding input's total disturbance (u(0) = u0)
            o_eso = iq[IQ_OESO]
            o_td = iq[IQ_OTD]
            for l in range(_W):
                z[o_eso, l] = _PH(fns, z[:, l], p[:, l]) + s[S_NOISE, l]
                zt[o_eso, l] = z[o_eso, l]
                z[o_eso + rho, l] = -q[L.F_B0, l] * q[L.F_ESO_U0, l]
                zt[o_eso + rho, l] = z[o_eso + rho, l]
                if init_td:
                    z[o_td, l] = z[o_eso, l]
                    zt[o_td, l] = z[o_eso, l]
        for st in range(n_stages):
            c = STAGE_TIME[method, st]
            ri = int(2.0 * c)  # the reference slot of t_k + c dt: 0, 1 (mid-step), 2 (end)
            if delayed and not _SAMPLED:  # y and u at this stage of step k - m into s
                _DELAY_STAGE_IN(k, st, n_stages, s, ring, dsteps)
            _RHS(fns, (k + c) * dt, zt, kd, iq, q, p, pn, rrs, ri, s, dany)
            if delayed and not _SAMPLED:  # this stage's y and command into the ring
                _DELAY_STAGE_OUT(k, st, n_stages, s, ring, fns, zt, p)
            if st == 0:
                stored = store and save_in == 0
                if stored:
                    _STORE_ROW(row, t, lanes, live, rows, z, s, rrs, iq, ctrl, tr)
                    row += 1
                    save_in = decimation
                save_in -= 1
                # the plant at t_k: watched, and stopped as lost when out of its envelope
                # (its trajectory ends with this point, stored if the decimation skipped it)
                _WATCH(t, dt, k < n_steps, lanes, live, s, z, rrs, sc, batch, stv)
                for l in range(_W):
                    if live[l] and s[S_LOST, l] != 0.0:
                        if store and not stored and row < tr.shape[1]:
                            alone[l] = True
                            _STORE_ROW(row, t, lanes, alone, rows, z, s, rrs, iq, ctrl, tr)
                            alone[l] = False
                        _STOP_LANE(l, t, L.STATUS_LOST, lanes, live, z, stv, out)
                        n_live -= 1
                if k == n_steps or n_live == 0:
                    break
            last = st == n_stages - 1
            next_h = STAGE_NEXT[method, st] * dt
            _BLK_STAGE(z, zt, kd, acc, nza, st == 0, last, next_h, STAGE_WEIGHT[method, st], scale)
        if k == n_steps or n_live == 0:
            break
        if n_stages > 1:
            for j in range(nd_stage + 1):
                _BLK_COPY(rrs[2, j], rrs[0, j])
        # divergence, lane by lane: a plant state's |x| < threshold fails (also for NaN);
        # the integrals and the controller's states only when they are no longer finite
        _BLK_OUT_OF_RANGE(z, _N, nza, threshold, s[S_BAD])
        if _SAMPLED:
            _CONTROLLER_BAD(rho, iq[IQ_NTD], s, ctrl)
        for l in range(_W):
            if live[l] and s[S_BAD, l] != 0.0:
                _STOP_LANE(l, (k + 1) * dt, L.STATUS_DIVERGED, lanes, live, z, stv, out)
                n_live -= 1
        if n_live == 0:
            break
    _FINISH_LANES(lanes, real, live, rows, row, z, stv, out)
    _KEEP_ALIVE(lane_owner, real_owner, live_owner, rows_owner, switched_owner, iq_owner)
    _KEEP_ALIVE(q_owner, qt_owner, ctrl_owner, rl_owner, z_owner, p_owner)
    _KEEP_ALIVE(sc_owner, s_owner, rr_owner, rrow_owner, nrow_owner, nrow_owner)
    _KEEP_ALIVE(dsteps, ring, nper_owner, next_owner, due_owner, st_owner)


def _tpl_store_row(row, t, lanes, live, rows, z, s, rrs, iq, ctrl, tr):  # pragma: no cover
    """One trajectory row of every live lane: t, r, y, y_meas, u, d, the plant state, the
    observer's estimate ξ̂ and the differentiator's profile (the columns of
    :func:`aiofl.layout.trajectory_columns`)."""
    rho = iq[IQ_RHO]
    exact = iq[IQ_TD] == L.TD_EXACT
    ntd = iq[IQ_NTD]
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
            tr[mi, row, c0 + j] = _STORE_CONTROLLER(0, j, rho, ntd, exact, l, z, iq, rrs, ctrl)
        c0 += L.RHO_MAX + 1
        for j in range(L.RHO_MAX):
            tr[mi, row, c0 + j] = _STORE_CONTROLLER(1, j, rho, ntd, exact, l, z, iq, rrs, ctrl)
        rows[l] = row + 1


def _tpl_reference(t, t_hold, sc, ref_t, rrow, rr, oi, nd, kind, s):  # pragma: no cover
    """r(t) and derivatives 0..nd of every lane into ``rr[oi, k, l]``; ``t_hold`` is the
    start of the step (a step reference is held over it); the kind is uniform in a group."""
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
            s[S_SIN],
            s[S_COS],
            s[S_AMP],
        )
        for k in range(1, nd + 1):  # d^k/dt^k sin = sin(ph + k π/2)
            _BLK_SINE_DERIVATIVE(k % 4, sc[L.S_REF_OMEGA], s[S_SIN], s[S_COS], s[S_AMP], rr[oi, k])
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
            for j in range(pp.shape[1]):
                pp[3, j, l] = pp[1, j, l]
    return dany


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


def _tpl_load_lanes(lanes, batch, pp, sc, rrow, nrow, zz):  # pragma: no cover - compiled
    """Each lane's member data into the group's columns: plant parameters (before and
    after the change, nominal, now = before: ``pp[0..3]``), scenario row, table rows and
    the initial plant state (``zz[0]`` and the stage state ``zz[1]``)."""
    for l in range(_W):
        mi = lanes[l]
        for j in range(pp.shape[1]):
            pp[0, j, l] = batch.p_before[mi, j]
            pp[1, j, l] = batch.p_after[mi, j]
            pp[2, j, l] = batch.p_nom[mi, j]
            pp[3, j, l] = batch.p_before[mi, j]
        for j in range(L.N_SCEN):
            sc[j, l] = batch.scen[mi, j]
        rrow[l] = batch.ref_row[mi]
        nrow[l] = batch.noise_row[mi]
        for i in range(_N):
            zz[0, i, l] = batch.x0[mi, i]
            zz[1, i, l] = batch.x0[mi, i]


def _tpl_start_members(lanes, real, out):  # pragma: no cover - compiled
    """The real lanes' members: status OK, no stop time (yet)."""
    for l in range(_W):
        if real[l]:
            out.status[lanes[l]] = L.STATUS_OK
            out.t_stop[lanes[l]] = np.nan


def _tpl_watch(t, dt, counted, lanes, live, s, z, rrs, sc, batch, stv):  # pragma: no cover
    r"""Every live lane's plant at step start :math:`t_k`, after the step's first stage
    (``s[S_Y]`` = :math:`y = h(x_k)`, ``s[S_U]`` the command over the step, ``rrs[0, 0]``
    = :math:`r(t_k)`): the statistics ``stv`` (:data:`aiofl.layout.ST_U_PEAK` ..; the
    saturation time and the steady-state window count a step only when ``counted``, i.e.
    one follows), and ``s[S_LOST]`` = 1 when the plant is out of its envelope:
    :math:`|y - r|` above ``scenario.envelope``, y or a state outside the range its
    member's ``batch.bounds`` declares (rows 0..n-1 the states, row n the output).  A
    NaN compares false: a non-finite plant is diverged, not lost."""
    for l in range(_W):
        if not live[l]:
            continue
        mi = lanes[l]
        y = s[S_Y, l]
        r = rrs[0, 0, l]
        u = s[S_U, l]
        e = y - r
        ae = abs(e)
        au = abs(u)
        if au > stv[L.ST_U_PEAK, l]:
            stv[L.ST_U_PEAK, l] = au
        if ae > stv[L.ST_E_PEAK, l]:
            stv[L.ST_E_PEAK, l] = ae
        if counted:
            u_max = batch.floats[mi, L.F_UMAX]
            u_min = batch.floats[mi, L.F_UMIN]
            u_min = -u_max if u_min != u_min else u_min  # NaN: a symmetric range
            if u >= u_max or u <= u_min:
                stv[L.ST_T_SAT, l] += dt
        if sc[L.S_REF_KIND, l] == L.REF_STEP:  # step metrics, from the step on
            a = sc[L.S_REF_A, l]
            r0 = sc[L.S_REF_OFFSET, l]
            if a != 0.0 and abs(r - r0) >= 0.5 * abs(a):
                prog = (y - r0) if a > 0.0 else (r0 - y)  # progress towards r0 + A
                if prog > stv[L.ST_STEP_PEAK, l]:
                    stv[L.ST_STEP_PEAK, l] = prog
                if stv[L.ST_T10, l] != stv[L.ST_T10, l] and prog >= 0.1 * abs(a):
                    stv[L.ST_T10, l] = t
                if stv[L.ST_T90, l] != stv[L.ST_T90, l] and prog >= 0.9 * abs(a):
                    stv[L.ST_T90, l] = t
                if not ae < 0.02 * abs(a):
                    stv[L.ST_T_OUT, l] = t
        if counted and t >= sc[L.S_STEADY_FROM, l]:
            if stv[L.ST_SS_N, l] == 0.0:
                stv[L.ST_SS_U0, l] = u
                stv[L.ST_U_LAST, l] = u
            du = u - stv[L.ST_SS_U0, l]
            stv[L.ST_SS_N, l] += 1.0
            stv[L.ST_SS_SU, l] += du
            stv[L.ST_SS_SU2, l] += du * du
            stv[L.ST_SS_SE, l] += e
            jump = u - stv[L.ST_U_LAST, l]  # the command's step-to-step change
            if jump != 0.0:
                stv[L.ST_SS_DU2, l] += jump * jump
                stv[L.ST_SS_NDU, l] += 1.0
            stv[L.ST_U_LAST, l] = u
        stv[L.ST_Y_END, l] = e
        lost = ae > sc[L.S_ENVELOPE, l]
        lost = lost or y < batch.bounds[mi, _N, 0] or y > batch.bounds[mi, _N, 1]
        for j in range(_N):
            xj = z[j, l]
            lost = lost or xj < batch.bounds[mi, j, 0] or xj > batch.bounds[mi, j, 1]
        s[S_LOST, l] = 1.0 if lost else 0.0


def _tpl_stop_lane(l, t, status, lanes, live, z, stv, out):  # pragma: no cover - compiled
    """Lane l's member was lost or diverged (``status``) at t: reported with its integrals
    and statistics so far, lane masked."""
    live[l] = False
    mi = lanes[l]
    out.status[mi] = status
    out.t_stop[mi] = t
    for j in range(L.N_METRIC):
        out.metrics[mi, j] = z[_N + j, l]
    for j in range(L.N_STAT):
        out.stats[mi, j] = stv[j, l]


def _tpl_finish_lanes(lanes, real, live, rows, row, z, stv, out):  # pragma: no cover
    """After the horizon: the live lanes' integrals and statistics; stored rows after each
    member's last one (where it was lost or diverged) set to NaN."""
    tr = out.traj
    for l in range(_W):
        if live[l]:
            mi = lanes[l]
            for j in range(L.N_METRIC):
                out.metrics[mi, j] = z[_N + j, l]
            for j in range(L.N_STAT):
                out.stats[mi, j] = stv[j, l]
            rows[l] = row
    if tr.shape[1] > 0:
        for l in range(_W):
            if real[l]:
                mi = lanes[l]
                for rw in range(rows[l], tr.shape[1]):
                    for j in range(tr.shape[2]):
                        tr[mi, rw, j] = np.nan


def _tpl_keep_alive(a, b, c, d, e, f):  # pragma: no cover - compiled
    """A use of the arrays that own the memory of unmanaged views, so they live until here."""
    return a.size + b.size + c.size + d.size + e.size + f.size
