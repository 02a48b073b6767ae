r"""The closed loop of the analyses, compiled, with its exact Jacobian (forward mode).

:func:`loop_eval` is one numba-compiled evaluation of the right-hand side
:math:`F(z; r, \tau_d, n, u_p)` that :class:`aiofl.analysis.closed_loop.ClosedLoop`
writes in Python (``rhs``, the reference the tests compare it with), together with its
directional derivatives along K given *tangent* directions of the state and the inputs:
forward-mode differentiation, each quantity carried as its value and its K derivatives,
so one call gives :math:`F`, :math:`y`, :math:`u` and :math:`\partial(F, y, u)/\partial z
\cdot T` exactly (to rounding) for any seed matrix T (the identity: the Jacobian; an
input's column: a column of B or D).

The controller's pieces are written here with their derivatives (they are linear, or
scalar functions whose slopes are known: fal, the INLSEF terms, the INLESO injection, the
ITD's tanh, the saturation by its branch).  The plant enters as numbers: the values and
Jacobians of its functions at the real state (:meth:`CompiledLoop.plant_jets`, from
:class:`aiofl.analysis.derivatives.PlantDerivatives`: the complex step of the plant's own
functions, or finite differences where that fails), so any plant works and no plant is
compiled here.  The module calls no other module's compiled code, so its disk cache
(``cache=True``) cannot go stale when another file changes.

How the non-smooth scalars are treated is a mode (``nl_mode``): 0, the secant gains of
the linearisation (:class:`ClosedLoop` ``"linearise"``); 1, the exact functions with
their slopes (:class:`aiofl.analysis.orbit_loop.OrbitLoop`); 2, given describing gains
(the harmonic balance).  The exact values use plain ``pow``/``tanh`` where the engine's
components use their fast-math forms (:mod:`aiofl.components.fastmath`): they agree to a
few ulp.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numba import njit
from numpy.typing import NDArray

__all__ = [
    "F_B0",
    "N_FLOAT_HEAD",
    "SLOPE_FLOOR",
    "float_offsets",
    "loop_eval",
]

SLOPE_FLOOR = 1e-12
"""|e| below which the slope of :math:`|e|^{a}`, a < 1, is taken at this value."""

# integer settings (ints): positions
I_N, I_NTD, I_RHO, I_M, I_TD, I_ESO, I_SEF, I_LAW, I_NL, I_BD = range(10)
N_INTS = 10
# td kinds: exact profile, Han's outputs as inputs, improved TD (21), linear prefilter
TD_EXACT, TD_HAN, TD_IMPROVED, TD_LINEAR = range(4)
# law kinds: AIOFL, AIOFL with the nominal model in the observer, classical IOFL
LAW_AIOFL, LAW_MODEL, LAW_IOFL = range(3)

# float settings (flt): scalars, then the arrays at float_offsets(rho, m)
F_B0, F_UMIN, F_UMAX, F_KINJ, F_ITD_BOC, F_ITD_GAIN, F_ITD_RR, F_VL = range(8)
F_KA, F_KB, F_GA, F_GB, F_DINJ = range(8, 13)
N_FLOAT_HEAD = 16
"""Scalars before the arrays of the float settings."""


@njit(cache=True)
def float_offsets(rho: int, m: int) -> tuple[int, int, int, int, int, int]:
    """Offsets in the float settings of the observer gains β (ρ+1), the linear SEF gains
    (ρ), the SEF's secant or describing gains (m), the SEF parameters (4 per term), the
    prefilter's coefficients (ρ), and the total length."""
    ob = N_FLOAT_HEAD
    ol = ob + rho + 1
    og = ol + rho
    os_ = og + m
    op = os_ + 4 * m
    return ob, ol, og, os_, op, op + rho


@njit(cache=True)
def _pow_slope(e: float, a: float) -> float:
    """:math:`a|e|^{a-1}` (|e| floored at :data:`SLOPE_FLOOR`)."""
    if a == 1.0:
        return 1.0
    return a * max(abs(e), SLOPE_FLOOR) ** (a - 1.0)


@njit(cache=True)
def _sign(e: float) -> float:
    if e > 0.0:
        return 1.0
    if e < 0.0:
        return -1.0
    return 0.0


@njit(cache=True)
def _fal(e: float, a: float, delta: float) -> tuple[float, float]:
    """fal (17) and its slope (δ^(α−1) inside δ, α|e|^(α−1) outside)."""
    if abs(e) <= delta:
        s = delta ** (a - 1.0)
        return e * s, s
    return abs(e) ** a * _sign(e), _pow_slope(e, a)


@njit(cache=True)
def _inlsef(e: float, k1: float, k2: float, mu: float, a: float) -> tuple[float, float]:
    """The INLSEF term (20) and its slope."""
    sig = 1.0 / (1.0 + math.exp(min(mu * e * e, 700.0))) if k2 != 0.0 else 0.0
    gain = k1 + k2 * sig
    ae = abs(e)
    value = gain * ae**a * _sign(e)
    d_sig = -sig * (1.0 - sig) * 2.0 * mu * e if k2 != 0.0 else 0.0
    return value, gain * _pow_slope(e, a) + k2 * d_sig * ae**a * _sign(e)


@njit(cache=True)
def _injection(e: float, ka: float, kb: float, ga: float, gb: float) -> tuple[float, float]:
    """The INLESO injection g(e) (19) and its slope."""
    ae = abs(e)
    g = ka * ae**ga * _sign(e)
    slope = ka * _pow_slope(e, ga)
    if kb != 0.0:
        g += kb * ae**gb * e
        slope += kb * (gb + 1.0) * ae**gb
    return g, slope


@njit(cache=True)
def _rows_times(pj: Any, r0: int, nr: int, nc: int, t: Any) -> Any:
    """``pj[r0:r0+nr, :nc] @ t`` written out (no BLAS call for a few numbers)."""
    k = t.shape[1]
    res = np.zeros((nr, k))
    for i in range(nr):
        for q in range(nc):
            c = pj[r0 + i, q]
            if c != 0.0:
                for j in range(k):
                    if t[q, j] != 0.0:  # 0·inf would spread to every column
                        res[i, j] += c * t[q, j]
    return res


@njit(cache=True)
def loop_eval(
    z: NDArray[np.float64],
    tz: NDArray[np.float64],
    rd: NDArray[np.float64],
    trd: NDArray[np.float64],
    inputs: NDArray[np.float64],
    tin: NDArray[np.float64],
    use_up: bool,
    ints: NDArray[np.int64],
    flt: NDArray[np.float64],
    pv: NDArray[np.float64],
    pj: NDArray[np.float64],
    out: NDArray[np.float64],
    tout: NDArray[np.float64],
) -> None:
    r"""The closed loop's :math:`(\dot z, y, u, e)` and their derivatives along K tangents.

    Parameters
    ----------
    z, tz
        The state (n_z,) and its tangents (n_z, K).
    rd, trd
        The reference and its derivatives (ρ+1,) (with Han's TD: its outputs r1, r2) and
        their tangents (ρ+1, K).
    inputs, tin
        (τ_d, n, u_p) and their tangents (3, K).
    use_up
        Whether the loop is broken at the plant input (the plant driven by u_p).
    ints, flt
        The loop's settings (:class:`CompiledLoop`).
    pv, pj
        The plant functions' values and Jacobians, stacked by rows: h (1), f (n), g (n),
        b_d (n), (α, β)(ξ̂) (2, Jacobian in ξ̂'s first ρ entries), the normal form (ρ+2).
    out, tout
        Filled: rows ż (n_z), y, u, then the inputs of the non-smooth functions (m SEF
        errors, the injection's error), and their tangents (rows × K).
    """
    n, n_td, rho, m = ints[I_N], ints[I_NTD], ints[I_RHO], ints[I_M]
    td_kind, eso, sef, law, nl = ints[I_TD], ints[I_ESO], ints[I_SEF], ints[I_LAW], ints[I_NL]
    has_bd = ints[I_BD] != 0
    k = tz.shape[1]
    o_td = n
    o_eso = n + n_td
    n_z = o_eso + rho + 1
    iy, iu, ie = n_z, n_z + 1, n_z + 2
    ob, ol, og, os_, op, _ = float_offsets(rho, m)
    b0, u_min, u_max = flt[F_B0], flt[F_UMIN], flt[F_UMAX]
    out[:] = 0.0
    tout[:, :] = 0.0
    # plant rows in pv / pj
    r_h, r_f = 0, 1
    r_g = r_f + n
    r_bd = r_g + n
    r_ab = r_bd + n
    r_nf = r_ab + 2
    tx = tz[:n]
    xi = z[o_eso : o_eso + rho + 1]
    txi = tz[o_eso : o_eso + rho + 1]
    r = rd[0]
    tr = trd[0]
    # ------------------------------------------------ reference profile (TD)
    prof = np.zeros(rho)
    tprof = np.zeros((rho, k))
    rff = 0.0
    trff = np.zeros(k)
    if td_kind == TD_EXACT:
        prof[:] = rd[:rho]
        tprof[:, :] = trd[:rho]
        rff = rd[rho]
        trff[:] = trd[rho]
    elif td_kind == TD_HAN:
        for i in range(min(2, rho)):
            prof[i] = rd[i]
            tprof[i] = trd[i]
    elif td_kind == TD_IMPROVED:
        boc, gain, rr = flt[F_ITD_BOC], flt[F_ITD_GAIN], flt[F_ITD_RR]
        t0, t1 = z[o_td], z[o_td + 1]
        th = math.tanh(boc * t0 - gain * r)
        out[o_td] = t1
        tout[o_td] = tz[o_td + 1]
        out[o_td + 1] = -rr * rr * th - rr * t1
        dth = 1.0 - th * th
        for j in range(k):
            tout[o_td + 1, j] = (
                -rr * rr * dth * (boc * tz[o_td, j] - gain * tr[j]) - rr * tz[o_td + 1, j]
            )
        for i in range(min(2, rho)):
            prof[i] = z[o_td + i]
            tprof[i] = tz[o_td + i]
    else:  # linear prefilter
        acc = flt[op] * (r - z[o_td])
        tacc = flt[op] * (tr - tz[o_td])
        for i in range(1, rho):
            out[o_td + i - 1] = z[o_td + i]
            tout[o_td + i - 1] = tz[o_td + i]
            acc -= flt[op + i] * z[o_td + i]
            tacc -= flt[op + i] * tz[o_td + i]
        out[o_td + rho - 1] = acc
        tout[o_td + rho - 1] = tacc
        rff = acc
        trff[:] = tacc
        for i in range(rho):
            prof[i] = z[o_td + i]
            tprof[i] = tz[o_td + i]
    # ------------------------------------------------ plant output
    y = pv[r_h]
    ty = _rows_times(pj, r_h, 1, n, tx)[0]
    # ------------------------------------------------ law
    u = 0.0
    tu = np.zeros(k)
    a_hat = b_hat = 0.0
    ta_hat = np.zeros(k)
    tb_hat = np.zeros(k)
    if law == LAW_IOFL:
        lin_k = flt[ol : ol + rho]
        nf = pv[r_nf : r_nf + rho + 2]
        tnf = _rows_times(pj, r_nf, rho + 2, n, tx)
        acc = rff
        tacc = trff.copy()
        for i in range(m):
            acc += lin_k[i] * (prof[i] - nf[i])
            tacc += lin_k[i] * (tprof[i] - tnf[i])
        u = (-nf[rho] + acc) / nf[rho + 1]
        tu = (-tnf[rho] + tacc) / nf[rho + 1] - u * tnf[rho + 1] / nf[rho + 1]
    else:
        # SEF on e = profile - ξ̂
        e = prof[:m] - xi[:m]
        te = tprof[:m] - txi[:m]
        for i in range(m):
            out[ie + i] = e[i]
            tout[ie + i] = te[i]
        s = 0.0
        ts = np.zeros(k)
        if sef == 0:  # linear
            lin_k = flt[ol : ol + rho]
            s = rff
            ts[:] = trff
            for i in range(m):
                s += lin_k[i] * e[i]
                ts += lin_k[i] * te[i]
            s /= b0
            ts /= b0
        elif nl != 1:  # secant (linearise) or describing gains
            for i in range(m):
                s += flt[og + i] * e[i]
                ts += flt[og + i] * te[i]
            if nl == 2 and sef == 2:  # the INLSEF's limit on the describing loop
                vl = flt[F_VL]
                th = math.tanh(s / vl)
                ts *= 1.0 - th * th
                s = vl * th
        else:  # exact
            for i in range(m):
                q = os_ + 4 * i
                if sef == 1:
                    val, slope = _fal(e[i], flt[q + 1], flt[q + 2])
                    val *= flt[q]
                    slope *= flt[q]
                else:
                    val, slope = _inlsef(e[i], flt[q], flt[q + 1], flt[q + 2], flt[q + 3])
                s += val
                ts += slope * te[i]
            if sef == 2:
                vl = flt[F_VL]
                th = math.tanh(s / vl)
                ts *= 1.0 - th * th
                s = vl * th
        if law == LAW_MODEL:
            a_hat, b_hat = pv[r_ab], pv[r_ab + 1]
            tab = _rows_times(pj, r_ab, 2, rho, txi)
            ta_hat, tb_hat = tab[0], tab[1]
            num = b0 * s - a_hat - xi[rho]
            tnum = b0 * ts - ta_hat - txi[rho]
            u = num / b_hat
            tu = tnum / b_hat - u * tb_hat / b_hat
        else:
            u = s - xi[rho] / b0
            tu = ts - txi[rho] / b0
    # saturation: slope 1 inside, 0 at a limit
    if u > u_max:
        u = u_max
        tu[:] = 0.0
    elif u < u_min:
        u = u_min
        tu[:] = 0.0
    out[iy] = y
    tout[iy] = ty
    out[iu] = u
    tout[iu] = tu
    # ------------------------------------------------ observer
    ei = y + inputs[1] - xi[0]
    tei = ty + tin[1] - txi[0]
    out[ie + m] = ei
    tout[ie + m] = tei
    if eso == 0:
        inj = ei
        tinj = tei
    elif nl == 0:
        inj = flt[F_KINJ] * ei
        tinj = flt[F_KINJ] * tei
    elif nl == 2:
        inj = flt[F_DINJ] * ei
        tinj = flt[F_DINJ] * tei
    else:
        inj, slope = _injection(ei, flt[F_KA], flt[F_KB], flt[F_GA], flt[F_GB])
        tinj = slope * tei
    for i in range(rho):
        out[o_eso + i] = xi[i + 1] + flt[ob + i] * inj
        tout[o_eso + i] = txi[i + 1] + flt[ob + i] * tinj
    if law == LAW_MODEL:
        out[o_eso + rho - 1] += a_hat + b_hat * u
        tout[o_eso + rho - 1] += ta_hat + tb_hat * u + b_hat * tu
    else:
        out[o_eso + rho - 1] += b0 * u
        tout[o_eso + rho - 1] += b0 * tu
    out[o_eso + rho] = flt[ob + rho] * inj
    tout[o_eso + rho] = flt[ob + rho] * tinj
    # ------------------------------------------------ plant
    u_in = inputs[2] if use_up else u
    tu_in = tin[2] if use_up else tu
    d = inputs[0]
    tf = _rows_times(pj, r_f, n, n, tx)
    tg = _rows_times(pj, r_g, n, n, tx)
    for i in range(n):
        out[i] = pv[r_f + i] + pv[r_g + i] * u_in
        tout[i] = tf[i] + tg[i] * u_in + pv[r_g + i] * tu_in
    if has_bd:
        tb = _rows_times(pj, r_bd, n, n, tx)
        for i in range(n):
            out[i] += pv[r_bd + i] * d
            tout[i] += tb[i] * d + pv[r_bd + i] * tin[0]
