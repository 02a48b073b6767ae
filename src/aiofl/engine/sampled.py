r"""The sampled-data closed loop: a discrete controller on a continuous plant, compiled.

A member whose discrete row (:mod:`aiofl.engine.discrete`) has ``D_STEPS = N > 0`` runs
:func:`_tpl_member_sampled` instead of the continuous time loop: the plant and the
performance integrals are integrated as before (RK4 or Euler at ``dt``), and every N-th
step, at :math:`t_k = kT_s`, the controller reads the measurement, runs
:func:`_tpl_ctrl_step` once and its command is held until the next sample (see
:mod:`aiofl.engine.discrete` for the ADC, delay and DAC).  Like the continuous templates
of :mod:`aiofl.engine.kernel`, these functions are plain Python compiled per plant by
:func:`sampled_member_for` with the compile factory (:func:`sampled_recipe`);
members of one batch may mix continuous members and any sample times, and run in parallel.
This is the one-member sampled loop (``engine="scalar"``, the reference); the default engine
runs sampled members in SIMD lanes (:mod:`aiofl.engine.lanes_sampled`), calling this
module's controller update lane by lane.

The controller's update calls the same component functions as the continuous loop (the
INLESO injection, Han's TD (18), the ITD, saturation), the same compiled SEF-and-law
dispatch (:func:`aiofl.engine.kernel._aiofl_command`, :func:`~aiofl.engine.kernel._iofl_command`)
and the discrete ones of :mod:`aiofl.components.discrete` (ESO correction and prediction,
fhan, the prefilter's ZOH update), with the coefficients of the member's discrete row.  The
ESO starts as the continuous loop's does (``eso.init``: "zero", the default, or "output",
:math:`\hat\xi_1 = ` the first measurement; see :func:`_tpl_ctrl_init`).
:class:`DiscreteController` compiles the same :func:`_tpl_ctrl_step` without a plant and
steps it from Python: the engine's discrete controller, sample by sample (the C export is
checked against it).

Controller state of one member (``cs``)::

    [ TD / prefilter r_1..r_ρ (RHO_MAX) | ESO prediction p_1 - y, p_2, ... (RHO_MAX+1)
      | ESO estimate ξ̂ (RHO_MAX+1) | previous command | previous measurement
      | previous reference | profile r_1.. used (RHO_MAX) | scratch (RHO_MAX) ]

The classical IOFL law (no ESO, needs the plant state) runs sampled in the engine, from the
true state at :math:`t_k` and the nominal model, but has no :class:`DiscreteController`.
"""

from __future__ import annotations

import sys
import threading
from collections.abc import Callable, Sequence
from types import SimpleNamespace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from aiofl import layout as L
from aiofl.cache import cache_enabled
from aiofl.controller import Controller, controller_batch
from aiofl.engine import build, kernel
from aiofl.engine import compile as compile_
from aiofl.engine import discrete as DS
from aiofl.engine.discrete import (
    D_DELAY,
    D_GAM,
    D_H0,
    D_K,
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
    Sampling,
    sampling_rows,
)
from aiofl.engine.kernel import (
    IQ_EINIT,
    IQ_ESO,
    IQ_LAW,
    IQ_NTD,
    IQ_RHO,
    IQ_TD,
    N_IQ,
    N_Q,
    N_SIG,
    Q_ITD_BC,
    Q_ITD_GAIN,
    Q_PF,
    SWITCH_RTOL,
    _aiofl_command,
    _iofl_command,
)
from aiofl.plants.base import Plant

__all__ = ["DiscreteController", "member_dispatch", "sampled_member_for"]

C_TD = 0  #: differentiator / prefilter state
C_P = C_TD + L.RHO_MAX  #: ESO prediction p_k
C_X = C_P + L.RHO_MAX + 1  #: ESO estimate ξ̂_k (after the correction at the last sample)
C_UPREV = C_X + L.RHO_MAX + 1  #: the previous sample's command
C_Y = C_UPREV + 1  #: the previous sample's measurement (the ESO's first state is p_1 - y)
C_RPREV = C_Y + 1  #: the previous sample's reference (Han's TD keeps r_1 - r_prev)
C_PROF = C_RPREV + 1  #: the differentiator's profile r_1.. used at the last sample
C_SCR = C_PROF + L.RHO_MAX  #: scratch for the prefilter update
N_CS = C_SCR + L.RHO_MAX

# placeholders bound per instance (see _bind and aiofl.engine.kernel)
_N = _N_P = 1
_PF = _PG = _PH = _PBD = _PNF = None
_SETUP = _REFERENCE = _UNMANAGED = _KEEP_ALIVE = None
_CTRL_INIT = _CTRL_STEP = _PLANT_DERIV = None
_SATURATE = None
_INLESO = _HAN_TD = _ITD = _PREFILTER = None
_FHAN_TD = _OBS_INNOVATION = _OBS_CORRECT = _OBS_PREDICT = _LIN_UPDATE = None


# ---------------------------------------------------------------------------- templates
def _tpl_ctrl_init(iq, cs, y0):  # pragma: no cover - compiled
    r"""Controller state before the first sample, as the continuous loop starts its ESO
    (``eso.init``, :data:`aiofl.layout.ESO_INIT_KINDS`): the TD at rest at 0, the ESO's
    prediction :math:`p_0 = 0` (``"zero"``, the default) or :math:`p_0 = (y_0, 0, ..., 0)`
    with ``y0`` the first measurement (``"output"``: the first innovation is 0).

    The first sample's correction then gives :math:`\hat\xi_0 = L\,\phi(y_0)` or
    :math:`(y_0, 0, ..., 0)`.  :math:`p_1` is kept as its change since the previous
    measurement (``cs[C_P]``) and that measurement (``cs[C_Y]``): ``0, 0`` for zero,
    ``0, y0`` for output.
    """
    for i in range(N_CS):
        cs[i] = 0.0
    if iq[IQ_EINIT] == L.ESO_INIT_OUTPUT:
        cs[C_Y] = y0  # p_1 = y0: its change since the measurement, cs[C_P], is 0
        cs[C_X] = y0


def _tpl_ctrl_step(iq, q, dsc, cs, scr, y, rr, ri):  # pragma: no cover - compiled
    """One sample of the discrete AIOFL controller: returns u_k, updates ``cs``.

    ESO correction :math:`\\hat\\xi = p + L\\phi(y - p_1)`; errors
    :math:`e_i = r_i - \\hat\\xi_i` against the differentiator's profile at t_k (or the
    exact derivatives ``rr[ri]``); SEF (17)/(20)/linear and law (14), saturated; ESO
    prediction :math:`p^+ = \\Phi\\hat\\xi + \\Gamma u_m + K\\phi` with the command applied
    over the coming interval (:math:`u_{k-1}` with a one-sample delay); differentiator
    update to t_{k+1}.
    """
    rho = iq[IQ_RHO]
    n1 = rho + 1
    td_kind = iq[IQ_TD]
    exact = td_kind == L.TD_EXACT
    ts = dsc[D_TS]

    e = _OBS_INNOVATION(cs, C_P, C_Y, y)  # y - p_1
    phi = e
    if iq[IQ_ESO] == L.ESO_IMPROVED:  # eq. (19)
        phi = _INLESO(e, q[L.F_KA], q[L.F_KB], q[L.F_EA], q[L.F_EB])
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

    # SEF and law (14), the continuous loop's formulas (aiofl.engine.kernel._aiofl_command)
    u = _aiofl_command(iq, q, rr, ri, cs, C_PROF, cs, C_X, rff)
    u = _SATURATE(u, q[L.F_UMIN], q[L.F_UMAX])  # actuator range [u_min, u_max]

    um = cs[C_UPREV] if dsc[D_DELAY] > 0.0 else u
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
    cs[C_UPREV] = u
    return u


def _tpl_plant_deriv(t, z, dz, p, u, d, r, xb):  # pragma: no cover - compiled
    """Plant (1) under the held command u and the integrands of eq. (22); returns y."""
    for i in range(_N):
        xb[i] = z[i]
    y = _PH(xb, p)
    fx = _PF(xb, p)
    gx = _PG(xb, p)
    for i in range(_N):
        dz[i] = fx[i] + gx[i] * u
    if d != 0.0:
        bdx = _PBD(xb, p)
        for i in range(_N):
            dz[i] += bdx[i] * d
    err = abs(y - r)
    dz[_N + L.M_ITAE] = t * err
    dz[_N + L.M_IAE] = err
    dz[_N + L.M_ISE] = err * err
    dz[_N + L.M_ISU] = u * u
    dz[_N + L.M_IAU] = abs(u)
    return y


def _tpl_member_sampled(  # pragma: no cover - compiled
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
    disc,
):
    """Integrate sampled member ``mi`` (same arguments as the continuous time loop, plus
    the batch's discrete rows ``disc``); every array of the loop is thread-local."""
    nr = L.RHO_MAX + 2
    nza = _N + L.N_METRIC
    work_owner = np.zeros(N_Q + N_DISC + 2 * N_CS + 4 * nza + _N + 4 * _N_P + L.N_SCEN)
    iq_owner = np.zeros(N_IQ, dtype=np.int64)
    rr_owner = np.zeros((4, nr))  # r at t, t + dt/2, t + dt; r and derivatives at t_k
    w = _UNMANAGED(work_owner)
    iq = _UNMANAGED(iq_owner)
    rrs = _UNMANAGED(rr_owner)
    ref_t = _UNMANAGED(ref_table)
    noise_t = _UNMANAGED(noise_table)
    tr = _UNMANAGED(traj)
    o = 0
    q = w[o : o + N_Q]
    o += N_Q
    dsc = w[o : o + N_DISC]
    o += N_DISC
    cs = w[o : o + N_CS]
    o += N_CS
    scr = w[o : o + N_CS]
    o += N_CS
    z = w[o : o + nza]
    o += nza
    zt = w[o : o + nza]
    o += nza
    kd = w[o : o + nza]
    o += nza
    acc = w[o : o + nza]
    o += nza
    xb = w[o : o + _N]
    o += _N
    pb = w[o : o + _N_P]
    o += _N_P
    pa = w[o : o + _N_P]
    o += _N_P
    pn = w[o : o + _N_P]
    o += _N_P
    p = w[o : o + _N_P]
    o += _N_P
    sc = w[o : o + L.N_SCEN]
    _SETUP(ints[mi], floats[mi], q, iq)
    for j in range(N_DISC):
        dsc[j] = disc[mi, j]
    n_per = int(dsc[D_STEPS])
    delay = dsc[D_DELAY] > 0.0
    yq = dsc[D_YQ]
    uq = dsc[D_UQ]
    rho = iq[IQ_RHO]
    ntd = iq[IQ_NTD]
    exact = iq[IQ_TD] == L.TD_EXACT
    iofl = iq[IQ_LAW] == L.LAW_IOFL
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
    t_change = sc[L.S_PCHANGE_TIME] * (1.0 - SWITCH_RTOL)
    t_dist = sc[L.S_DIST_TIME] * (1.0 - SWITCH_RTOL)
    rk4 = method == L.METHOD_RK4
    hdt = 0.5 * dt
    sixth = dt / 6.0
    status[mi] = L.STATUS_OK
    t_div[mi] = np.nan
    row = 0
    save_in = 0
    ua = 0.0  # the command the plant gets over the current sample interval
    ym = 0.0  # the measurement of the last sample
    for k in range(n_steps + 1):
        t = k * dt
        noise_val = 0.0
        if std > 0.0:  # held over [i hold, (i+1) hold)
            idx = int(t / hold + 1e-9)
            noise_val = std * noise_t[nrow, idx if idx < n_noise else n_noise - 1]
        d = sc[L.S_DIST_AMP] if t >= t_dist else 0.0
        if not switched and t >= t_change:
            for j in range(_N_P):
                p[j] = pa[j]
            switched = True
        if k % n_per == 0 and k < n_steps:  # a sample: ADC, controller, DAC
            for i in range(_N):
                xb[i] = z[i]
            ym = _PH(xb, p) + noise_val
            if yq > 0.0:
                ym = yq * np.floor(ym / yq + 0.5)
            _REFERENCE(t, t, sc, ref_t, rrow, rrs, 3, nd)
            if k == 0:
                _CTRL_INIT(iq, cs, ym)
            u_before = cs[C_UPREV]
            if iofl:  # classical IOFL from the true state and the nominal model
                nfx = _PNF(xb, pn)
                uc = _iofl_command(iq, q, rrs, 3, cs, C_PROF, nfx, rrs[3, rho])
                uc = _SATURATE(uc, q[L.F_UMIN], q[L.F_UMAX])
                cs[C_UPREV] = uc
            else:
                uc = _CTRL_STEP(iq, q, dsc, cs, scr, ym, rrs, 3)
            ua = u_before if delay else uc
            if uq > 0.0:
                ua = uq * np.floor(ua / uq + 0.5)
        _REFERENCE(t, t, sc, ref_t, rrow, rrs, 0, 0)
        if rk4:
            _REFERENCE((k + 0.5) * dt, t, sc, ref_t, rrow, rrs, 1, 0)
            _REFERENCE((k + 1) * dt, t, sc, ref_t, rrow, rrs, 2, 0)
        y = _PLANT_DERIV(t, zt, kd, p, ua, d, rrs[0, 0], xb)
        if store and save_in == 0:
            tr[mi, row, 0] = t
            tr[mi, row, 1] = rrs[0, 0]
            tr[mi, row, 2] = y
            tr[mi, row, 3] = ym
            tr[mi, row, 4] = ua
            tr[mi, row, 5] = d
            for j in range(_N):
                tr[mi, row, N_SIG + j] = z[j]
            c0 = N_SIG + _N
            for j in range(L.RHO_MAX + 1):
                tr[mi, row, c0 + j] = cs[C_X + j] if j <= rho and not iofl else 0.0
            c0 += L.RHO_MAX + 1
            for j in range(L.RHO_MAX):
                val = 0.0
                if exact and j < rho:
                    val = rrs[3, j]
                elif j < ntd:
                    val = cs[C_PROF + j]  # the profile the last sample used
                tr[mi, row, c0 + j] = val
            row += 1
            save_in = decimation
        save_in -= 1
        if k == n_steps:
            break
        if not rk4:  # forward Euler
            for j in range(nza):
                z[j] += dt * kd[j]
                zt[j] = z[j]
        else:
            for j in range(nza):
                acc[j] = kd[j]
                zt[j] = z[j] + hdt * kd[j]
            _PLANT_DERIV((k + 0.5) * dt, zt, kd, p, ua, d, rrs[1, 0], xb)
            for j in range(nza):
                acc[j] += 2.0 * kd[j]
                zt[j] = z[j] + hdt * kd[j]
            _PLANT_DERIV((k + 0.5) * dt, zt, kd, p, ua, d, rrs[1, 0], xb)
            for j in range(nza):
                acc[j] += 2.0 * kd[j]
                zt[j] = z[j] + dt * kd[j]
            _PLANT_DERIV((k + 1) * dt, zt, kd, p, ua, d, rrs[2, 0], xb)
            for j in range(nza):
                z[j] += sixth * (acc[j] + kd[j])
                zt[j] = z[j]
        bad = not abs(ua) < threshold
        for j in range(nza):
            if not abs(z[j]) < threshold:  # also catches NaN
                bad = True
        for j in range(C_P, C_P + rho + 1):  # (the first is p_1 - y)
            if not abs(cs[j]) < threshold:
                bad = True
        for j in range(ntd):
            if not abs(cs[C_TD + j]) < threshold:
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
    _KEEP_ALIVE(work_owner, iq_owner, rr_owner)


# ------------------------------------------------------------------------------ building
def _bind(ns: dict[str, Any], cd: Any = None) -> None:
    """Add this module's layout constants and the discrete component functions to ``ns``
    (those of ``cd``, default :mod:`aiofl.components.discrete`; the lane kernel passes its
    private copies, see :func:`aiofl.engine.build.private_components`)."""
    if cd is None:
        from aiofl.components import discrete as cd

    ns.update({k: v for k, v in vars(DS).items() if k.isupper() and isinstance(v, int)})
    ns.update({k: v for k, v in globals().items() if k.startswith("C_") or k == "N_CS"})
    ns.update(
        _FHAN_TD=cd.fhan_td_step,
        _OBS_INNOVATION=cd.observer_innovation,
        _OBS_CORRECT=cd.observer_correct,
        _OBS_PREDICT=cd.observer_predict,
        _LIN_UPDATE=cd.linear_discrete_update,
    )


def _opts() -> dict[str, Any]:
    from aiofl.components.fastmath import FASTMATH

    return {"fastmath": FASTMATH, "error_model": "numpy"}


def _sources() -> tuple[str, ...]:
    """Every kernel's sources, this module's and the discrete coefficient rows'."""
    return (*build.engine_sources(), sys.modules[__name__].__file__, DS.__file__)


def sampled_recipe(plant: Plant) -> compile_.Recipe:
    """The recipe of the one-member sampled-data kernel of ``plant``: the scalar kernel's
    namespace with the discrete components bound, the controller's init and update, the
    plant's right-hand side (inlined) and the sampled time loop as entry."""
    ns = build.plant_namespace(plant)
    _bind(ns)
    opts = _opts()
    tpl = compile_.Template
    return compile_.Recipe(
        kind="sampled",
        plant=plant,
        bindings=ns,
        templates=(
            tpl("_KEEP_ALIVE", kernel._tpl_keep_alive),
            tpl("_SETUP", kernel._tpl_setup, opts),
            tpl("_REFERENCE", kernel._tpl_reference, opts),
            tpl("_CTRL_INIT", _tpl_ctrl_init, opts),
            tpl("_CTRL_STEP", _tpl_ctrl_step, opts),
            tpl("_PLANT_DERIV", _tpl_plant_deriv, {"inline": "always", **opts}),
        ),
        entry=tpl("member", _tpl_member_sampled, {"nogil": True, **opts}),
        sources=_sources(),
    )


def _build_sampled(plant: Plant) -> Any:
    return compile_.build(sampled_recipe(plant), cache=cache_enabled()).entry


_MEMBERS: dict[int, tuple[Plant, Any]] = {}
_LOCK = threading.Lock()


def sampled_member_for(plant: Plant) -> Any:
    """The compiled sampled-data time loop of ``plant`` (built on first use, cached on disk
    like the continuous kernel)."""
    key = id(plant)
    with _LOCK:
        if key not in _MEMBERS or _MEMBERS[key][0] is not plant:
            _MEMBERS[key] = (plant, _build_sampled(plant))
        return _MEMBERS[key][1]


def member_dispatch(
    plant: Plant, continuous: Any, disc: NDArray[np.float64]
) -> Callable[..., None]:
    """A member function for :func:`aiofl.engine.build.run_members` that runs member i
    sampled when ``disc[i, D_STEPS] > 0`` and with ``continuous`` otherwise (the choice is
    made once per member, in Python; the time loops are compiled)."""
    sampled = sampled_member_for(plant)
    steps = disc[:, D_STEPS]

    def member(i: int, *args: Any) -> None:
        if steps[i] > 0:
            sampled(i, *args, disc)
        else:
            continuous(i, *args)

    return member


_STANDALONE: list[SimpleNamespace] = []


def _standalone() -> SimpleNamespace:
    """The controller update compiled without a plant (for :class:`DiscreteController`)."""
    with _LOCK:
        if not _STANDALONE:
            ns = dict(vars(kernel))
            ns.update(_N=1, _N_P=1, _NZ=1, **build.component_functions())
            _bind(ns)
            opts = _opts()
            tpl = compile_.Template
            recipe = compile_.Recipe(
                kind="standalone",
                plant=None,
                bindings=ns,
                templates=(
                    tpl("_SETUP", kernel._tpl_setup, opts),
                    tpl("_CTRL_INIT", _tpl_ctrl_init, opts),
                ),
                entry=tpl("_CTRL_STEP", _tpl_ctrl_step, opts),
                sources=_sources(),
            )
            space = compile_.build(recipe, cache=False).namespace
            _STANDALONE.append(
                SimpleNamespace(
                    setup=space["_SETUP"], init=space["_CTRL_INIT"], step=space["_CTRL_STEP"]
                )
            )
        return _STANDALONE[0]


class DiscreteController:
    """The engine's discrete controller, stepped from Python one sample at a time.

    The same compiled update the sampled engine runs (:func:`_tpl_ctrl_step`), with the
    coefficients of :func:`aiofl.engine.discrete.sampling_rows`.  One call per sample:
    :meth:`init` with the first measurement, then :meth:`step` with the reference (and its
    derivatives) and the measurement, returning u.

    Parameters
    ----------
    controller
        An AIOFL controller (LESO, INLESO, LADRC, ...); the IOFL law needs the plant state
        and is refused.
    sampling
        Sample time and discretisation.
    """

    def __init__(self, controller: Controller, sampling: Sampling) -> None:
        if controller.law != "aiofl":
            raise ValueError(
                f"controller.law_kind = {controller.law!r}: a discrete controller without "
                "the plant needs the AIOFL law (the IOFL law evaluates the plant model)"
            )
        sampling.check(controller)
        self.controller = controller
        self.sampling = sampling
        batch = controller_batch(controller)
        self.row = sampling_rows(batch, [sampling], sampling.ts)[0]
        self._fn = _standalone()
        self._q = np.zeros(N_Q)
        self._iq = np.zeros(N_IQ, dtype=np.int64)
        self._fn.setup(batch.ints[0], batch.floats[0], self._q, self._iq)
        self._cs = np.zeros(N_CS)
        self._scr = np.zeros(N_CS)
        self._rr = np.zeros((1, L.RHO_MAX + 2))

    def init(self, y0: float) -> None:
        r"""Reset the states for the first measurement ``y0``: the differentiator at rest
        at 0 and the ESO as ``controller.eso_init`` says (``"zero"``, the default:
        prediction 0, ``y0`` unused; ``"output"``: :math:`\hat\xi_1 = y_0`, the other
        states 0), as the continuous loop starts it."""
        self._fn.init(self._iq, self._cs, float(y0))

    def step(self, r: float | Sequence[float] | NDArray[np.float64], y: float) -> float:
        """One sample: ``r`` = r (or r, ṙ, ..., r^(ρ)) at t_k, ``y`` the measurement; returns u."""
        rv = np.atleast_1d(np.asarray(r, dtype=np.float64))
        self._rr[0, :] = 0.0
        self._rr[0, : rv.size] = rv
        return float(
            self._fn.step(self._iq, self._q, self.row, self._cs, self._scr, y, self._rr, 0)
        )

    @property
    def estimate(self) -> NDArray[np.float64]:
        """The ESO estimate ξ̂ after the last sample's correction (ρ+1 values)."""
        return self._cs[C_X : C_X + self.controller.rho + 1].copy()

    @property
    def differentiator(self) -> NDArray[np.float64]:
        """The differentiator's (or prefilter's) state, already advanced to the next sample."""
        out = self._cs[C_TD : C_TD + L.RHO_MAX].copy()
        if self.controller.td == "han":  # kept as r_1 - r_prev
            out[0] += self._cs[C_RPREV]
        return out
