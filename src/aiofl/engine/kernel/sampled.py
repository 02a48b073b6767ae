r"""The discrete controller: what a processor runs at the samples, and its place in the loop.

A member whose discrete row (:mod:`aiofl.engine.discrete_rows`) has ``D_STEPS = N > 0`` runs the
time loop's sampled instance (:mod:`aiofl.engine.kernel.loop` with ``_SAMPLED``): the plant and the
performance integrals are integrated at ``dt`` (:func:`_tpl_plant_deriv`, the loop's
right-hand side between samples), and every N-th step, at :math:`t_k = kT_s`,
:func:`_tpl_sample` runs the controller of the member's lane once (each lane has its own N,
so members of different sample times share a group; a lane between its samples holds its
measurement, reference and command): the ADC reads the measurement,
:func:`_tpl_ctrl_step` updates the controller, the DAC holds its command until the next
sample (see :mod:`aiofl.engine.discrete_rows` for the delay and the quantisers).  The update is
scalar, lane by lane, on the member's row of a lane-major controller state; between samples
the plant runs in SIMD lanes.

The update calls the same component functions as the continuous controller (the INLESO
injection, Han's TD (18), the ITD, saturation), the same compiled SEF-and-law dispatch
(:func:`aiofl.engine.kernel.member._aiofl_command`,
:func:`~aiofl.engine.kernel.member._iofl_command`) and the discrete ones of
:mod:`aiofl.components.discrete` (ESO correction and prediction, fhan, the prefilter's ZOH
update), with the coefficients of the member's discrete row.  The ESO starts as the
continuous loop's does (``eso.init``, ``eso.u0``: :func:`_tpl_ctrl_init`).  The same
:func:`_tpl_ctrl_step` compiled without a plant
(:mod:`aiofl.engine.build.controller_update`) is what :class:`aiofl.DiscreteController`
steps from Python, sample by sample (the C export is checked against it).

Controller state of one member (``cs``)::

    [ TD / prefilter r_1..r_ρ (RHO_MAX) | ESO prediction p_1 - y, p_2, ... (RHO_MAX+1)
      | ESO estimate ξ̂ (RHO_MAX+1) | previous command | previous measurement
      | previous reference | profile r_1.. used (RHO_MAX) | scratch (RHO_MAX) ]

The classical IOFL law (no ESO, needs the plant state) runs sampled in the engine, from the
true state at :math:`t_k` and the nominal model, but has no :class:`DiscreteController`.
"""

from __future__ import annotations

import numpy as np

from aiofl import layout as L
from aiofl.engine.discrete_rows import (
    D_DELAY,
    D_GAM,
    D_H0,
    D_K,
    D_KDELAY,
    D_L,
    D_PF_GAM,
    D_PF_PHI,
    D_PHI,
    D_STEPS,
    D_TDM,
    D_TS,
    D_UQ,
    D_YQ,
    N_DISC,
    PF_STRIDE,
    STRIDE,
    TDM_FHAN,
)
from aiofl.engine.kernel.loop import (
    S_BAD,
    S_D,
    S_NOISE,
    S_U,
    S_UC,
    S_UREF,
    S_Y,
    S_YD,
    S_YDON,
    S_YM,
    S_YS,
)
from aiofl.engine.kernel.member import (
    IQ_EINIT,
    IQ_ESO,
    IQ_LAW,
    IQ_MODEL,
    IQ_NTD,
    IQ_RHO,
    IQ_TD,
    Q_ITD_BC,
    Q_ITD_GAIN,
    Q_PF,
    _aiofl_command,
)

__all__: list[str] = []  # templates, bound per instance (aiofl.engine.build.instances)

C_TD = 0  #: differentiator / prefilter state
C_P = C_TD + L.RHO_MAX  #: ESO prediction p_k
C_X = C_P + L.RHO_MAX + 1  #: ESO estimate ξ̂_k (after the correction at the last sample)
C_UPREV = C_X + L.RHO_MAX + 1  #: the previous sample's command
C_Y = C_UPREV + 1  #: the previous sample's measurement (the ESO's first state is p_1 - y)
C_RPREV = C_Y + 1  #: the previous sample's reference (Han's TD keeps r_1 - r_prev)
C_PROF = C_RPREV + 1  #: the differentiator's profile r_1.. used at the last sample
C_SCR = C_PROF + L.RHO_MAX  #: scratch for the prefilter update
#: older commands u_{k-2}, u_{k-3}, ... (a known delay's ESO input, ``eso.delay``)
C_UHIST = C_SCR + L.RHO_MAX
#: the last references r, r', ..., one row of RHO_MAX + 1 per sample, newest first
C_RHIST = C_UHIST + L.KNOWN_DELAY_MAX
C_RFILL = C_RHIST + L.KNOWN_DELAY_MAX * (L.RHO_MAX + 1)  #: 1 once the rows hold references
N_CS = C_RFILL + 1

# Placeholders: stand-ins so this module imports.  The loop's templates (_tpl_setup,
# _tpl_sample, _tpl_plant_deriv, ...) are filled per sampled instance by
# aiofl/engine/build/instances.py:recipe; the update's (_tpl_ctrl_init, _tpl_ctrl_step, ...)
# by the same recipe (``ns_ctrl``) and, without a plant, by
# aiofl/engine/build/controller_update.py:update_recipe.
_W = 32  # lane width: 32, or 1 for a lone member
_N = 1  # the plant's number of states
# the plant's normal form and α-β (aiofl/engine/build/plant_table.py:direct_bindings or
# call_bindings; without a plant: direct_binding of the model's alpha_beta_of_xi)
_PNF = _PAB = None
_MEMBER_SETUP = _IOFL_COMMAND = None  # kernel.member's, compiled for the instance
_LEADING_ROWS = _COLUMN = None  # kernel.views.leading_rows_intrinsic(), lane_column_intrinsic()
# the update's templates, compiled for the instance (instances.recipe: compile_.instantiate;
# controller_update.update_recipe: its templates and entry)
_CTRL_INIT = _CTRL_STEP = _DELAY_REFERENCE = None
# the lane blocks the plant needs between samples (kernel.lane_blocks)
_BLK_OUTPUT = _BLK_PLANT_OUTPUT = _BLK_PLANT = _BLK_DISTURBANCE = _BLK_METRICS = None
# the component functions (aiofl/engine/build/bindings.py:component_functions)
_SATURATE = _INLESO = _HAN_TD = _ITD = _PREFILTER = None
# the discrete component functions (aiofl/engine/build/bindings.py:bind_discrete)
_FHAN_TD = _OBS_INNOVATION = _OBS_CORRECT = _OBS_PREDICT = _LIN_UPDATE = None
PLACEHOLDERS = tuple(
    """
    _W _N _PNF _PAB _MEMBER_SETUP _IOFL_COMMAND _LEADING_ROWS _COLUMN _CTRL_INIT _CTRL_STEP
    _DELAY_REFERENCE _BLK_OUTPUT _BLK_PLANT_OUTPUT _BLK_PLANT _BLK_DISTURBANCE _BLK_METRICS
    _SATURATE _INLESO _HAN_TD _ITD _PREFILTER _FHAN_TD _OBS_INNOVATION _OBS_CORRECT
    _OBS_PREDICT _LIN_UPDATE
    """.split()  # noqa: SIM905 - the names as a reader scans them
)
"""The names of the placeholder block: what the compile factory checks a recipe binds
when a template of this module reads one (:func:`aiofl.engine.build.compile.build`)."""


# ---------------------------------------------------------------------------- templates
def _tpl_ctrl_init(iq, q, cs, y0):  # pragma: no cover - compiled
    r"""Controller state before the first sample, as the continuous loop starts its ESO
    (``eso.init``, :data:`aiofl.layout.ESO_INIT_KINDS`): the TD at rest at 0, the ESO's
    prediction :math:`p_0 = 0` (``"zero"``, the default) or :math:`p_0 = (y_0, 0, ..., 0)`
    with ``y0`` the first measurement (``"output"``: the first innovation is 0); with
    ``"bumpless"`` that prediction and the TD at rest at ``y0`` (:math:`r_1 = y_0`).
    Started at ``y0``, the extended state is at :math:`-b_0 u_0` (``eso.u0``: the total
    disturbance of a plant held by :math:`u_0`), so the first command is :math:`u_0`, also
    the one applied before the first sample (a delayed command's first interval).
    :math:`p_1` is kept as its change since the previous measurement (``cs[C_P]``) and that
    measurement (``cs[C_Y]``): ``0, 0`` for zero, ``0, y0`` for output.
    """
    for i in range(N_CS):
        cs[i] = 0.0
    if iq[IQ_EINIT] != L.ESO_INIT_ZERO:  # "output" or "bumpless"
        cs[C_Y] = y0  # p_1 = y0: its change since the measurement, cs[C_P], is 0
        cs[C_X] = y0
        rho = iq[IQ_RHO]
        cs[C_P + rho] = -q[L.F_B0] * q[L.F_ESO_U0]
        cs[C_X + rho] = cs[C_P + rho]
        cs[C_UPREV] = q[L.F_ESO_U0]
        for j in range(L.KNOWN_DELAY_MAX):  # held before the start, as far back as it reads
            cs[C_UHIST + j] = q[L.F_ESO_U0]
    if iq[IQ_EINIT] == L.ESO_INIT_BUMPLESS and iq[IQ_TD] != L.TD_EXACT:
        if iq[IQ_TD] == L.TD_HAN:
            cs[C_RPREV] = y0  # Han's TD keeps r_1 - r_prev = 0 with r_prev = y0
        else:
            cs[C_TD] = y0  # the ITD's / prefilter's r_1 at rest at y0


def _tpl_ctrl_step(fns, iq, q, dsc, cs, scr, y, rr, ri, pn):  # pragma: no cover - compiled
    """One sample of the discrete AIOFL controller: returns u_k, updates ``cs``.

    ESO correction :math:`\\hat\\xi = p + L\\phi(y - p_1)`; errors
    :math:`e_i = r_i - \\hat\\xi_i` against the differentiator's profile at t_k (or the
    exact derivatives ``rr[ri]``); SEF (17)/(20)/linear and law (14), saturated; ESO
    prediction :math:`p^+ = \\Phi\\hat\\xi + \\Gamma u_m + K\\phi` with the command applied
    over the coming interval (:math:`u_{k-1}` with a one-sample delay); differentiator
    update to t_{k+1}.

    With the model-assisted observer (``eso.model = "nominal"``) the nominal
    :math:`\\hat\\alpha, \\hat\\beta` are evaluated at the corrected estimate,
    :math:`(\\alpha_0, \\beta_0)(\\Phi^{-1}(\\hat\\xi_k))` with the nominal parameters
    ``pn``, the law is :func:`aiofl.components.law.model_assisted_law` and the prediction's
    input :math:`b_0 u_m` becomes :math:`\\hat\\alpha + \\hat\\beta u_m` (held over the
    interval, as u is).
    """
    rho = iq[IQ_RHO]
    n1 = rho + 1
    td_kind = iq[IQ_TD]
    exact = td_kind == L.TD_EXACT
    ts = dsc[D_TS]
    known = int(dsc[D_KDELAY])  # the known measurement delay d, in samples
    if known > 0:  # the reference d samples old, aligned with the measurement: rr[ri] <- it
        _DELAY_REFERENCE(cs, rr, ri, n1, known)

    e = _OBS_INNOVATION(cs, C_P, C_Y, y)  # y - p_1
    phi = e
    if iq[IQ_ESO] == L.ESO_IMPROVED:  # eq. (19)
        phi = _INLESO(
            e, q[L.F_ESO_K_ALPHA], q[L.F_ESO_K_BETA], q[L.F_ESO_G_ALPHA], q[L.F_ESO_G_BETA]
        )
    dx1 = _OBS_CORRECT(cs, C_P, C_X, n1, dsc, D_L, y, e, phi)

    # the profile r_1.. at t_k (Han's TD keeps r_1 as its change since the last reference,
    # so fhan's argument r_1 - r is formed from small numbers); the exact TD's are rr[ri]
    r = rr[ri, 0]
    rff = 0.0
    if exact:
        rff = rr[ri, rho]
    elif td_kind == L.TD_HAN:
        cs[C_PROF] = cs[C_RPREV] + cs[C_TD]
        cs[C_PROF + 1] = cs[C_TD + 1]
    else:
        for i in range(iq[IQ_NTD]):
            cs[C_PROF + i] = cs[C_TD + i]
        if td_kind == L.TD_LINEAR:
            rff = _PREFILTER(cs, scr, C_TD, rho, r, q, Q_PF)

    a_hat = 0.0
    b_hat = q[L.F_B0]
    model = iq[IQ_MODEL] == L.ESO_MODEL_NOMINAL
    if model:  # the nominal normal form at x̂ = Φ⁻¹(ξ̂)
        ab = _PAB(fns, cs[C_X : C_X + rho], pn)
        a_hat = ab[0]
        b_hat = ab[1]

    # SEF and law (14), the continuous loop's formulas (aiofl.engine.kernel.member._aiofl_command)
    u = _aiofl_command(iq, q, rr, ri, cs, C_PROF, cs, C_X, rff, a_hat, b_hat)
    u = _SATURATE(u, q[L.F_UMIN], q[L.F_UMAX])  # actuator range [u_min, u_max]

    # the command the plant got over the interval the measurements span: u_k, u_{k-1} with
    # the computation delay, and d samples older with a known measurement delay
    lag = int(dsc[D_DELAY]) + known
    um = u if lag == 0 else (cs[C_UPREV] if lag == 1 else cs[C_UHIST + lag - 2])
    if model:  # Γ holds b0: its input is (α̂ + β̂ u_m)/b0
        um = (a_hat + b_hat * um) / q[L.F_B0]
    _OBS_PREDICT(cs, C_P, C_X, C_Y, n1, dsc, D_PHI, STRIDE, D_GAM, D_K, um, phi, y, dx1)

    if td_kind == L.TD_HAN:  # both forms depend on r_1 - r only; keep r_1(k+1) - r_k
        x1 = cs[C_TD] - (r - cs[C_RPREV])
        r2 = cs[C_TD + 1]
        if dsc[D_TDM] == TDM_FHAN:
            a, b = _FHAN_TD(x1, r2, 0.0, q[L.F_TD_R], ts, dsc[D_H0])
        else:  # forward Euler on eq. (18)
            d1, d2 = _HAN_TD(x1, r2, 0.0, q[L.F_TD_R])
            a = x1 + ts * d1
            b = r2 + ts * d2
        cs[C_TD] = a
        cs[C_TD + 1] = b
        cs[C_RPREV] = r
    elif td_kind == L.TD_IMPROVED:  # forward Euler on eq. (21)
        d1, d2 = _ITD(cs[C_TD], cs[C_TD + 1], r, q[Q_ITD_BC], q[Q_ITD_GAIN], q[L.F_TD_RHO])
        a = cs[C_TD] + ts * d1
        cs[C_TD + 1] = cs[C_TD + 1] + ts * d2
        cs[C_TD] = a
    elif td_kind == L.TD_LINEAR:  # exact ZOH
        _LIN_UPDATE(cs, C_TD, rho, dsc, D_PF_PHI, PF_STRIDE, D_PF_GAM, r, scr, C_SCR)
    for j in range(lag - 2, 0, -1):  # the commands a known delay reads, one sample older
        cs[C_UHIST + j] = cs[C_UHIST + j - 1]
    if lag >= 2:
        cs[C_UHIST] = cs[C_UPREV]
    cs[C_UPREV] = u
    return u


def _tpl_delay_reference(cs, rr, ri, n1, d):  # pragma: no cover - compiled
    """Replace the reference values ``rr[ri, :n1]`` (r, r', ... at t_k) by those of d
    samples ago, and keep them: the controller then tracks :math:`r(t_k - dT_s)`, aligned
    with a measurement d samples old (its first call holds the first values over the past)."""
    nr = L.RHO_MAX + 1
    if cs[C_RFILL] == 0.0:
        for j in range(d):
            for i in range(n1):
                cs[C_RHIST + j * nr + i] = rr[ri, i]
        cs[C_RFILL] = 1.0
    for i in range(n1):
        now = rr[ri, i]
        rr[ri, i] = cs[C_RHIST + (d - 1) * nr + i]
        for j in range(d - 1, 0, -1):
            cs[C_RHIST + j * nr + i] = cs[C_RHIST + (j - 1) * nr + i]
        cs[C_RHIST + i] = now


def _tpl_ctrl_run(fns, iq, q, dsc, cs, scr, y, rr, ri, pn, n):  # pragma: no cover - compiled
    """``n`` samples of :func:`_tpl_ctrl_step` with the same measurement ``y`` and
    reference ``rr[ri]`` (a controller settling at an operating point); returns the last
    u, ``cs`` updated."""
    u = 0.0
    keep = rr[ri].copy()  # a known delay's step replaces rr[ri] by older values
    for _ in range(n):
        rr[ri] = keep
        u = _CTRL_STEP(fns, iq, q, dsc, cs, scr, y, rr, ri, pn)
    return u


def _tpl_ctrl_step_each(fns, iq, q, dsc, states, scr, ys, rr, ri, pn, us):  # pragma: no cover
    """One sample of :func:`_tpl_ctrl_step` from each row of ``states`` (updated in place)
    with measurement ``ys[k]``, its command into ``us[k]``: the perturbed states of a
    finite-difference Jacobian in one call."""
    keep = rr[ri].copy()  # a known delay's step replaces rr[ri] by older values
    for k in range(states.shape[0]):
        rr[ri] = keep
        us[k] = _CTRL_STEP(fns, iq, q, dsc, states[k], scr, ys[k], rr, ri, pn)


# ---------------------------------------------------- in the time loop, lane by lane
def _tpl_setup(lanes, batch, q, qt, iq, ctrl, nper):  # pragma: no cover - compiled
    """Per-member constants of the group's lanes, one row per lane (``q[l]``, read by the
    scalar controller update), their discrete rows (``ctrl[0, l]``) and the group's ``iq``
    (kinds are uniform within a group, so every lane writes the same); each lane's steps
    per sample N into ``nper[l]`` (the lanes of a group may sample at different periods)."""
    for l in range(_W):
        mi = lanes[l]
        _MEMBER_SETUP(batch.ints[mi], batch.floats[mi], q[l], iq)
        for j in range(N_DISC):
            ctrl[0, l, j] = batch.disc[mi, j]
        nper[l] = int(ctrl[0, l, D_STEPS])


def _tpl_sample(fns, k, z, p, pn, s, rrs, rl, iq, q, ctrl, due):  # pragma: no cover - compiled
    """A sample at t_k of the lanes ``due`` (the others hold everything): the ADC
    (``s[S_YM]`` = y + noise, quantised), the discrete controller's update
    (:func:`_tpl_ctrl_step`, or the classical IOFL law from the true state and the nominal
    model) with the reference and its derivatives at t_k (``rrs[4]``, kept in ``rrs[3]``
    until the lane's next sample), and the DAC (the command, delayed a sample if asked,
    quantised, held in ``s[S_U]`` until the next sample)."""
    rho = iq[IQ_RHO]
    nr = L.RHO_MAX + 2
    iofl = iq[IQ_LAW] == L.LAW_IOFL
    _BLK_OUTPUT(fns, z, p, s[S_NOISE], s[S_Y], s[S_YS])
    for l in range(_W):
        if not due[l]:
            continue
        # y(t_k) + n(t_k), or with a sensor delay y(t_k - τ_out) + n(t_k)
        ym = s[S_YD, l] + s[S_NOISE, l] if s[S_YDON, l] != 0.0 else s[S_YS, l]
        dsc = ctrl[0, l]
        cs = ctrl[1, l]
        yq = dsc[D_YQ]
        yl = yq * np.floor(ym / yq + 0.5) if yq > 0.0 else ym
        s[S_YM, l] = yl
        for j in range(nr):
            rrs[3, j, l] = rrs[4, j, l]
            rl[0, j] = rrs[4, j, l]
        if k == 0:
            _CTRL_INIT(iq, q[l], cs, yl)
        u_before = cs[C_UPREV]
        if iofl:
            nfx = _PNF(fns, _COLUMN(z, l), _COLUMN(pn, l))
            uc = _IOFL_COMMAND(iq, q[l], rl, 0, cs, C_PROF, nfx, rl[0, rho])
            uc = _SATURATE(uc, q[l, L.F_UMIN], q[l, L.F_UMAX])
            cs[C_UPREV] = uc
        else:
            uc = _CTRL_STEP(fns, iq, q[l], dsc, cs, ctrl[2, l], yl, rl, 0, _COLUMN(pn, l))
        ua = u_before if dsc[D_DELAY] > 0.0 else uc
        uq = dsc[D_UQ]
        s[S_U, l] = uq * np.floor(ua / uq + 0.5) if uq > 0.0 else ua


def _tpl_delay_output(fns, k, z, p, s, ring, dsteps):  # pragma: no cover - compiled
    r"""Step k's output :math:`y(t_k)` into the ring (slot k mod its length) and the
    delayed :math:`y(t_k - m\,dt)` into ``s[S_YD]`` (:math:`y(0)` while
    :math:`t_k < m\,dt`); the ADC reads it (:func:`_tpl_sample`)."""
    nb = ring.shape[1]
    _BLK_PLANT_OUTPUT(fns, z, p, ring[1, k % nb])
    for l in range(_W):
        m = dsteps[1, l]
        s[S_YD, l] = ring[1, (k - m) % nb, l] if k >= m else ring[1, 0, l]


def _tpl_delay_input(k, due, s, ring, dsteps):  # pragma: no cover - compiled
    r"""Step k's held command into the ring and the plant's :math:`u(t_k - m\,dt)` into
    ``s[S_U]`` (0 while :math:`t_k < m\,dt`); the controller's own held command is kept
    in ``s[S_UC]`` (set from the DAC at a lane's sample, ``due``).  The command is constant
    over each step, so the delayed one is too: the delay is exact."""
    nb = ring.shape[1]
    slot = k % nb
    for l in range(_W):
        if due[l]:
            s[S_UC, l] = s[S_U, l]
        ring[0, slot, l] = s[S_UC, l]
        m = dsteps[0, l]
        if m > 0:
            s[S_U, l] = ring[0, (k - m) % nb, l] if k >= m else 0.0


def _tpl_plant_deriv(fns, t, z, dz, iq, q, p, pn, rr, ri, s, dany):  # pragma: no cover - compiled
    """The plant under the held command ``s[S_U]`` and the integrands of eq. (22), every
    lane (the time loop's right-hand side between samples); y into ``s[S_Y]``."""
    _BLK_PLANT_OUTPUT(fns, z, p, s[S_Y])
    dx = _LEADING_ROWS(dz, _N)
    _BLK_PLANT(fns, z, p, s[S_U], dx)
    if dany:
        _BLK_DISTURBANCE(fns, z, p, s[S_D], dx)
    m0 = _N
    r = rr[ri, 0]
    du = dz[m0 : m0 + L.N_METRIC]
    _BLK_METRICS(t, s[S_Y], r, s[S_U], s[S_UREF], du[0], du[1], du[2], du[3], du[4])


def _tpl_controller_bad(rho, ntd, s, ctrl):  # pragma: no cover - compiled
    """Adds to ``s[S_BAD, l]`` when lane l's command, ESO prediction or differentiator
    state is no longer finite (a large but finite controller state is not a verdict: the
    plant's own state and envelope decide, :func:`aiofl.engine.kernel.loop._tpl_watch`)."""
    for l in range(_W):
        cs = ctrl[1, l]
        bad = not abs(s[S_U, l]) < np.inf
        for j in range(C_P, C_P + rho + 1):  # (the first is p_1 - y)
            bad = bad or not abs(cs[j]) < np.inf
        for j in range(ntd):
            bad = bad or not abs(cs[C_TD + j]) < np.inf
        if bad:
            s[S_BAD, l] += 1.0


def _tpl_store_controller(which, j, rho, ntd, exact, l, z, iq, rrs, ctrl):  # pragma: no cover
    """Trajectory column j of lane l: the ESO estimate ξ̂_{j+1} after the last sample's
    correction (``which`` 0; 0 for the IOFL law, which has none) or the profile r_{j+1}
    the last sample used (``which`` 1; the reference's derivative for the exact TD)."""
    cs = ctrl[1, l]
    if which == 0:
        return cs[C_X + j] if j <= rho and iq[IQ_LAW] != L.LAW_IOFL else 0.0
    if exact and j < rho:
        return rrs[3, j, l]
    if j < ntd:
        return cs[C_PROF + j]
    return 0.0
