r"""One member's constants and its law: what every engine instance computes per member.

The time loop (:mod:`aiofl.engine.kernel.loop`) advances members in groups; what is the same for
every timing and width is written here once:

- the packed per-member constants (:func:`_tpl_setup`): the controller's float row
  followed by quantities derived from it once per member (observer gains
  :math:`\beta_i = \alpha_i\omega_0^i`, feedback gains, fal's inner slopes, the linear
  prefilter's coefficients, the ITD's constants) and an integer row of kinds and offsets
  (:data:`IQ_ESO` ...);
- the state error feedback and the law (:func:`_aiofl_command`, :func:`_iofl_command`),
  which the continuous controller (:mod:`aiofl.engine.kernel.continuous`, IOFL lane by lane) and
  the discrete controller (:mod:`aiofl.engine.kernel.sampled`) call.

The controller's formulas are not written here: they call the public scalar component
functions of :mod:`aiofl.components` (fal, NLSEF, INLSEF, linear SEF, the laws), bound into
each instance as private copies (:func:`aiofl.engine.build.bindings.private_components`).
:func:`_tpl_setup` is a *template*: plain Python that reads the component functions as
module globals (placeholders here), compiled per instance by :mod:`aiofl.engine.build.compile`.

This module's source is part of the cache fingerprint of every kernel.
"""

from __future__ import annotations

from numba import njit

from aiofl import layout as L
from aiofl.components import feedback as _fb
from aiofl.components import law as _law
from aiofl.components.fastmath import FASTMATH

# ----------------------------------------------------------------------------- layout
# Per-member packed parameters (thread-local inside the kernel): the controller's float row
# followed by quantities derived from it once per member.
Q_BETA = L.N_FLOAT  #: observer gains β_i = α_i ω0^i, i = 1..ρ+1
Q_FEEDBACK_GAIN = Q_BETA + L.RHO_MAX + 1  #: feedback gains k_i (linear SEF / IOFL) or sef.k_i
Q_SLOPE = Q_FEEDBACK_GAIN + L.RHO_MAX  #: fal inner slopes δ_i^(α_i - 1)
Q_PF = Q_SLOPE + L.RHO_MAX  #: linear prefilter coefficients ω^ρ, C(ρ,i) ω^(ρ-i)
Q_ITD_BC = Q_PF + L.RHO_MAX  #: b/c of the ITD
Q_ITD_GAIN = Q_ITD_BC + 1  #: (1 - a)/c of the ITD
N_Q = Q_ITD_BC + 2
# Per-member integers: kinds, ρ, m, offsets of the TD and ESO blocks in z, active length,
# and how the ESO starts (layout.ESO_INIT_*).
IQ_ESO, IQ_TD, IQ_SEF, IQ_LAW, IQ_RHO, IQ_M, IQ_OTD, IQ_OESO, IQ_NZ, IQ_NTD, IQ_EINIT = range(11)
IQ_MODEL = 11  #: what the observer is given (layout.ESO_MODEL_*)
N_IQ = 12
N_SIG = 6  # t, r, y, y_meas, u, d
SWITCH_RTOL = 1e-12
"""A switching time t_s (step disturbance, parameter change, step reference) acts from the
first step whose start k·dt >= t_s (1 - SWITCH_RTOL): the tolerance absorbs the rounding of
k·dt, so a switch on the grid happens exactly at its step boundary."""


# Placeholders: stand-ins so this module imports.  _tpl_setup is compiled with a copy of this
# module's globals (its component modules and compiled laws re-bound to private copies,
# aiofl/engine/build/bindings.py:bind_private) updated by
# aiofl/engine/build/instances.py:recipe (``ns_member``) and
# aiofl/engine/build/controller_update.py:update_recipe (``ns``):
_N = 1  # the plant's number of states (1 in the update without a plant)
# the component functions (aiofl/engine/build/bindings.py:component_functions, private copies)
_ITD_CONSTANTS = _PREFILTER_COEF = _FAL_SLOPE = _LINEAR_SEF_GAIN = _ESO_GAIN = None
PLACEHOLDERS = tuple(
    """
    _N _ITD_CONSTANTS _PREFILTER_COEF _FAL_SLOPE _LINEAR_SEF_GAIN _ESO_GAIN
    """.split()  # noqa: SIM905 - the names as a reader scans them
)
"""The names of the placeholder block: what the compile factory checks a recipe binds
when a template of this module reads one (:func:`aiofl.engine.build.compile.build`)."""


# ------------------------------------------------------------ the law, written once
# The state error feedback and the law are the same formulas in the continuous controller
# (aiofl.engine.kernel.continuous) and in the discrete one (aiofl.engine.kernel.sampled):
# both call these.
# They depend on no plant function, so they are compiled once, here, and inlined (numba IR
# inlining) where called, so each caller compiles to the code it had with them in place.
@njit(inline="always", fastmath=FASTMATH, error_model="numpy")
def _aiofl_command(iq, q, rr, ri, ref, o_ref, xh, o_x, rff, a_hat, b_hat):  # pragma: no cover
    r"""The AIOFL command before saturation: SEF (17), (20) or linear, then law (14).

    With :math:`e_i = r_i - \hat\xi_i`, i = 1..m, the nonlinear SEF (17)
    :math:`v = \sum_i k_i\,\mathrm{fal}(e_i, \alpha_i, \delta_i)`, the INLSEF (20)
    :math:`v = v_{lim}\tanh\big(\sum_i (k_i + k_{b,i}/(1 + e^{\mu_i e_i^2}))
    |e_i|^{\alpha_i}\operatorname{sign} e_i \,/\, v_{lim}\big)` or the linear feedback of
    the chain :math:`v = (\sum_i k_i e_i + r^{(\rho)})/b_0`, and
    :math:`u = v - \hat\xi_{\rho+1}/b_0` (14), or with the model-assisted observer
    :math:`u = (b_0 v - \hat\alpha - \hat\xi_{\rho+1})/\hat\beta` with ``a_hat``,
    ``b_hat`` = :math:`\hat\alpha, \hat\beta` (:func:`aiofl.components.law.model_assisted_law`).

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
        v = _fb.inlsef_limit(acc, q[L.F_SEF_V_LIMIT])
    else:  # linear full-state feedback of the chain (14)
        acc = 0.0
        for i in range(m):
            acc += q[Q_FEEDBACK_GAIN + i] * ((rr[ri, i] if exact else ref[o_ref + i]) - xh[o_x + i])
        v = _fb.linear_sef(acc, rff, b0)
    if iq[IQ_MODEL] == L.ESO_MODEL_NOMINAL:
        return _law.model_assisted_law(v, xh[o_x + rho], b0, a_hat, b_hat)
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
        acc += q[Q_FEEDBACK_GAIN + i] * ((rr[ri, i] if exact else ref[o_ref + i]) - nfx[i])
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
        q[Q_BETA + i] = _ESO_GAIN(fp[L.F_ESO_ALPHA + i], w0, i + 1)
    if ip[L.I_SEF] == L.SEF_LINEAR or ip[L.I_LAW] == L.LAW_IOFL:
        for i in range(rho):
            q[Q_FEEDBACK_GAIN + i] = _LINEAR_SEF_GAIN(rho, i + 1, fp[L.F_SEF_OMEGA_C])
    else:
        for i in range(L.RHO_MAX):
            q[Q_FEEDBACK_GAIN + i] = fp[L.F_SEF_K + i]
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
    iq[IQ_MODEL] = ip[L.I_ESO_MODEL]
