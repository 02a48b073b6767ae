r"""The lane blocks of the time loop (:mod:`aiofl.engine.kernel.loop`): each formula of the closed
loop applied to every lane of a group, in a loop over the lanes that LLVM vectorizes.

Each block is one compiled function holding its loop over the lanes, so LLVM optimizes (and
vectorizes) that loop alone; the scalar formulas it calls (the component functions of
:mod:`aiofl.components`, the plant's f, g, h, b_d) are inlined into it.  A block takes every
quantity it writes as its own array (a row of the group's workspace), so that no two
arguments overlap (blocks are compiled with ``noalias``, see
:func:`aiofl.engine.build.instances._noalias_option`), and reaches per-lane plant states through
unmanaged views (no reference counting).  Multi-row outputs whose row stride LLVM cannot see
are written flat (state i of lane l at ``i W + l``).

Like the other templates these are plain Python until :mod:`aiofl.engine.build.instances`
compiles them with the globals of one plant and lane width (placeholders here).  This
module's source is part of every kernel's cache fingerprint.
"""

from __future__ import annotations

from aiofl import layout as L
from aiofl.engine.kernel.member import (
    Q_ITD_BC,
    Q_ITD_GAIN,
    SWITCH_RTOL,
)

FLOAT_MAX = 1.7976931348623157e308
"""The largest finite float64: ``abs(x) <= FLOAT_MAX`` is false for inf and NaN alike."""

# Placeholders: stand-ins so this module imports.  Filled per instance by
# aiofl/engine/build/instances.py:recipe (its ``ns.update``):
_W = 32  # lane width: 32, or 1 for a lone member
_N = 1  # the plant's number of states
# the plant's functions f-g, h, b_d, normal form, α-β: inlined or through the plant table
# (aiofl/engine/build/plant_table.py:direct_bindings or call_bindings)
_PFG = _PH = _PBD = _PNF = _PAB = None
_IOFL_COMMAND = None  # kernel.member._iofl_command, re-bound to the private components
_COLUMN = None  # kernel.views.lane_column_intrinsic()
_SIN = _COS = None  # the reference's sine and cosine: components.vecmath (lanes) or numpy
# the component functions (aiofl/engine/build/bindings.py:component_functions)
_HAN_TD = _ITD = _FAL = _FAL_POWER_NEEDED = _FAL_LINEAR = None
_INLSEF_TERM = _INLSEF_LIMIT = _LINEAR_SEF = _INLESO = _AIOFL_LAW = _SATURATE = None
_MODEL_ASSISTED_LAW = None
PLACEHOLDERS = tuple(
    """
    _W _N _PFG _PH _PBD _PNF _PAB _IOFL_COMMAND _COLUMN _SIN _COS _HAN_TD _ITD _FAL
    _FAL_POWER_NEEDED _FAL_LINEAR _INLSEF_TERM _INLSEF_LIMIT _LINEAR_SEF _INLESO _AIOFL_LAW
    _SATURATE _MODEL_ASSISTED_LAW
    """.split()  # noqa: SIM905 - the names as a reader scans them
)
"""The names of the placeholder block: what the compile factory checks a recipe binds
when a template of this module reads one (:func:`aiofl.engine.build.compile.build`)."""


def _blk_sine(t, a, w, phase, offset, with_cos, r, sn, cs, amp):  # pragma: no cover
    """r = a sin(ω t + φ) + offset; sin, cos of the phase and a kept for the derivatives."""
    for l in range(_W):
        ph = w[l] * t + phase[l]
        sl = _SIN(ph)
        r[l] = a[l] * sl + offset[l]
        sn[l] = sl
        cs[l] = _COS(ph) if with_cos else 0.0
        amp[l] = a[l]


def _blk_sine_derivative(j, w, sn, cs, amp, rk):  # pragma: no cover - compiled
    """The k-th derivative of the sine, k = j mod 4: amp ω^k sin(ph + k π/2) (amp *= ω)."""
    for l in range(_W):
        amp[l] *= w[l]
        v = sn[l] if j == 0 else cs[l]
        v = -sn[l] if j == 2 else v
        v = -cs[l] if j == 3 else v
        rk[l] = amp[l] * v


def _blk_step(t_hold, t_step, offset, a, r):  # pragma: no cover - compiled
    """A step reference, switched at a step boundary like every piecewise-constant input."""
    for l in range(_W):
        on = t_hold >= t_step[l] * (1.0 - SWITCH_RTOL)
        r[l] = offset[l] + (a[l] if on else 0.0)


def _blk_inputs(t, std, hold, noise_t, nrow, t_dist, amp, noise, d):  # pragma: no cover
    """The measurement noise (held over [i hold, (i+1) hold)) and the step disturbance of
    every lane at step start t."""
    n_noise = noise_t.shape[1]
    for l in range(_W):
        idx = int(t / hold[l] + 1e-9) if std[l] > 0.0 else 0
        idx = n_noise - 1 if idx >= n_noise else idx
        nv = std[l] * noise_t[nrow[l], idx]
        noise[l] = nv if std[l] > 0.0 else 0.0
        d[l] = amp[l] if t >= t_dist[l] * (1.0 - SWITCH_RTOL) else 0.0


def _blk_han(z, dz1, dz2, q, r, o, rff):  # pragma: no cover - compiled
    """Han's TD, eq. (18), every lane (differentiators.han_td_rhs)."""
    for l in range(_W):
        d1, d2 = _HAN_TD(z[o, l], z[o + 1, l], r[l], q[L.F_TD_R, l])
        dz1[l] = d1
        dz2[l] = d2
        rff[l] = 0.0


def _blk_itd(z, dz1, dz2, q, r, o, rff):  # pragma: no cover - compiled
    """The ITD, eq. (21), every lane (differentiators.improved_td_rhs_scaled)."""
    for l in range(_W):
        d1, d2 = _ITD(
            z[o, l], z[o + 1, l], r[l], q[Q_ITD_BC, l], q[Q_ITD_GAIN, l], q[L.F_TD_RHO, l]
        )
        dz1[l] = d1
        dz2[l] = d2
        rff[l] = 0.0


def _blk_prefilter_start(r1, c1, r, rff):  # pragma: no cover - compiled
    """Linear prefilter (differentiators.linear_prefilter_update): c_1 (r - r_1)."""
    for l in range(_W):
        rff[l] = c1[l] * (r[l] - r1[l])


def _blk_prefilter_term(ri1, ci1, dri, rff):  # pragma: no cover - compiled
    """Linear prefilter: dr_i = r_{i+1}, and - c_{i+1} r_{i+1} into the last derivative."""
    for l in range(_W):
        dri[l] = ri1[l]
        rff[l] -= ci1[l] * ri1[l]


def _blk_copy(src, dst):  # pragma: no cover - compiled
    """dst = src, every lane."""
    for l in range(_W):
        dst[l] = src[l]


def _blk_fill(dst, value):  # pragma: no cover - compiled
    """dst = value, every lane."""
    for l in range(_W):
        dst[l] = value


def _blk_output(fns, z, p, noise, y, ym):  # pragma: no cover - compiled
    """y = h(x) and y_meas = y + noise, every lane."""
    for l in range(_W):
        yl = _PH(fns, _COLUMN(z, l), _COLUMN(p, l))
        y[l] = yl
        ym[l] = yl + noise[l]


def _blk_plant_output(fns, z, p, y):  # pragma: no cover - compiled
    """y = h(x), every lane."""
    for l in range(_W):
        y[l] = _PH(fns, _COLUMN(z, l), _COLUMN(p, l))


def _blk_error(ri, xi, e):  # pragma: no cover - compiled
    """e_i = r_i - ξ̂_i, every lane."""
    for l in range(_W):
        e[l] = ri[l] - xi[l]


def _blk_fal(k, alpha, delta, slope, e, v):  # pragma: no cover - compiled
    """v += k_i fal(e_i, α_i, δ_i), eq. (17); the power |e_i|^α_i (a log and an exp) only
    when a lane of the group needs it (the same values: fal_linear is fal there)."""
    n_power = 0
    for l in range(_W):
        n_power += 1 if _FAL_POWER_NEEDED(e[l], alpha[l], delta[l]) else 0
    if n_power == 0:
        for l in range(_W):
            v[l] += k[l] * _FAL_LINEAR(e[l], delta[l], slope[l])
    else:
        for l in range(_W):
            v[l] += k[l] * _FAL(e[l], alpha[l], delta[l], slope[l])


def _blk_inlsef(k, kb, mu, alpha, e, v):  # pragma: no cover - compiled
    """The i-th term of the INLSEF sum, eq. (20)."""
    for l in range(_W):
        v[l] += _INLSEF_TERM(e[l], k[l], kb[l], mu[l], alpha[l])


def _blk_linear_term(k, e, v):  # pragma: no cover - compiled
    """v += k_i e_i (linear full-state feedback)."""
    for l in range(_W):
        v[l] += k[l] * e[l]


def _blk_inlsef_limit(v_lim, v):  # pragma: no cover - compiled
    """The INLSEF's output limit, eq. (20)."""
    for l in range(_W):
        v[l] = _INLSEF_LIMIT(v[l], v_lim[l])


def _blk_linear_sef(b0, rff, v):  # pragma: no cover - compiled
    """v = (sum + r^(rho))/b0, the linear SEF."""
    for l in range(_W):
        v[l] = _LINEAR_SEF(v[l], rff[l], b0[l])


def _blk_law(v, xi_ext, b0, u_min, u_max, u):  # pragma: no cover - compiled
    """u = sat(v - ξ̂_{ρ+1}/b0), eq. (14) and the actuator range."""
    for l in range(_W):
        u[l] = _SATURATE(_AIOFL_LAW(v[l], xi_ext[l], b0[l]), u_min[l], u_max[l])


def _blk_model(fns, z, o_eso, rho, pn, a_hat, b_hat):  # pragma: no cover - compiled
    """The nominal normal form at the observer's state, :math:`(\\hat\\alpha, \\hat\\beta)
    = (\\alpha_0, \\beta_0)(\\Phi^{-1}(\\hat\\xi))` (the plant's ``alpha_beta_of_xi`` with the
    nominal parameters), lane by lane."""
    for l in range(_W):
        ab = _PAB(fns, _COLUMN(z, l)[o_eso : o_eso + rho], _COLUMN(pn, l))
        a_hat[l] = ab[0]
        b_hat[l] = ab[1]


def _blk_model_law(v, xi_ext, b0, a_hat, b_hat, u_min, u_max, u):  # pragma: no cover
    """u = sat((b0 v - α̂ - ξ̂_{ρ+1})/β̂), the model-assisted law and the actuator range."""
    for l in range(_W):
        ul = _MODEL_ASSISTED_LAW(v[l], xi_ext[l], b0[l], a_hat[l], b_hat[l])
        u[l] = _SATURATE(ul, u_min[l], u_max[l])


def _blk_model_input(a_hat, b_hat, u, dxi):  # pragma: no cover - compiled
    """dξ̂_ρ += α̂ + β̂ u (the model-assisted observer's ρ-th equation)."""
    for l in range(_W):
        dxi[l] += a_hat[l] + b_hat[l] * u[l]


def _blk_iofl(fns, z, iq, q, pn, rr, ri, o_td, rff, u):  # pragma: no cover - compiled
    """The classical IOFL law on the nominal model, lane by lane (not vectorized)."""
    for l in range(_W):
        nfx = _PNF(fns, _COLUMN(z, l), _COLUMN(pn, l))  # views: no allocation per lane
        ul = _IOFL_COMMAND(iq, q[:, l], rr[:, :, l], ri, z[:, l], o_td, nfx, rff[l])
        u[l] = _SATURATE(ul, q[L.F_UMIN, l], q[L.F_UMAX, l])


def _blk_eso_error(ym, xi1, e):  # pragma: no cover - compiled
    """e = y_meas - ξ̂_1 (LESO)."""
    for l in range(_W):
        e[l] = ym[l] - xi1[l]


def _blk_inleso_error(ym, xi1, ka, kb, ea, eb, e):  # pragma: no cover - compiled
    """The INLESO's injection g(y_meas - ξ̂_1), eq. (19)."""
    for l in range(_W):
        e[l] = _INLESO(ym[l] - xi1[l], ka[l], kb[l], ea[l], eb[l])


def _blk_eso_row(xi_next, beta, e, dxi):  # pragma: no cover - compiled
    """dξ̂_i = ξ̂_{i+1} + β_i e (observers.eso_update)."""
    for l in range(_W):
        dxi[l] = xi_next[l] + beta[l] * e[l]


def _blk_eso_input(b0, u, dxi):  # pragma: no cover - compiled
    """dξ̂_ρ += b0 u (observers.eso_update)."""
    for l in range(_W):
        dxi[l] += b0[l] * u[l]


def _blk_eso_last(beta, e, dxi):  # pragma: no cover - compiled
    """dξ̂_{ρ+1} = β_{ρ+1} e (observers.eso_update)."""
    for l in range(_W):
        dxi[l] = beta[l] * e[l]


def _blk_plant(fns, z, p, u, dx):  # pragma: no cover - compiled
    """dx = f(x) + g(x) u, every lane (``dx`` flat: state i of lane l at i W + l, so LLVM
    sees that the rows do not overlap)."""
    for l in range(_W):
        fx, gx = _PFG(fns, _COLUMN(z, l), _COLUMN(p, l))
        for i in range(_N):
            dx[i * _W + l] = fx[i] + gx[i] * u[l]


def _blk_disturbance(fns, z, p, d, dx):  # pragma: no cover - compiled
    """dx += b_d(x) d where the lane's disturbance is on (``dx`` flat, as in _blk_plant)."""
    for l in range(_W):
        bdx = _PBD(fns, _COLUMN(z, l), _COLUMN(p, l))
        for i in range(_N):
            k = i * _W + l
            dx[k] = dx[k] + bdx[i] * d[l] if d[l] != 0.0 else dx[k]


def _blk_metrics(t, y, r, u, u_ref, itae, iae, ise, isu, iau):  # pragma: no cover - compiled
    """The integrands of ITAE, IAE, ISE, ISU, IAU (eq. 22), every lane; ISU and IAU of
    :math:`u - u_{ref}` (``scenario.u_ref``: 0, or the holding input at the operating
    point, so that holding the plant there costs nothing)."""
    for l in range(_W):
        err = abs(y[l] - r[l])
        du = u[l] - u_ref[l]
        itae[l] = t * err
        iae[l] = err
        ise[l] = err * err
        isu[l] = du * du
        iau[l] = abs(du)


def _blk_stage(z, zt, kd, acc, nza, first, last, h, w, scale):  # pragma: no cover
    """One stage of an explicit Runge-Kutta step (the stage tables of
    :mod:`aiofl.engine.kernel.loop`), every lane: the weighted sum of the stage derivatives
    ``acc`` gains ``w kd`` (``first``: starts at it) and the next stage's state is
    ``z + h kd``; after the ``last`` stage ``z += scale acc`` (forward Euler is one stage,
    both first and last: ``z += dt kd``)."""
    if first and last:
        for j in range(nza):
            for l in range(_W):
                z[j, l] += scale * kd[j, l]
                zt[j, l] = z[j, l]
    elif first:
        for j in range(nza):
            for l in range(_W):
                acc[j, l] = w * kd[j, l]
                zt[j, l] = z[j, l] + h * kd[j, l]
    elif last:
        for j in range(nza):
            for l in range(_W):
                z[j, l] += scale * (acc[j, l] + w * kd[j, l])
                zt[j, l] = z[j, l]
    else:
        for j in range(nza):
            for l in range(_W):
                acc[j, l] += w * kd[j, l]
                zt[j, l] = z[j, l] + h * kd[j, l]


def _blk_out_of_range(z, n_plant, nza, threshold, bad):  # pragma: no cover - compiled
    """bad[l] = the number of entries of lane l's state out of range: the plant's first
    ``n_plant`` with |z| >= threshold (or NaN), the rest (integrals, controller states)
    when no longer finite."""
    for l in range(_W):
        bad[l] = 0.0
    for j in range(n_plant):
        for l in range(_W):
            bad[l] += 0.0 if abs(z[j, l]) < threshold else 1.0
    for j in range(n_plant, nza):
        for l in range(_W):
            bad[l] += 0.0 if abs(z[j, l]) <= FLOAT_MAX else 1.0
