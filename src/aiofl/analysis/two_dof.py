r"""Linear ADRC as an ordinary two-degree-of-freedom controller: feedback C and prefilter F.

A linear ADRC — linear ESO of order ρ+1, linear state error feedback with the poles of
:math:`(s+\omega_c)^\rho`, the law (14) :math:`u = (v - \hat\xi_{\rho+1})/b_0`, and a
linear prefilter :math:`\omega^\rho/(s+\omega)^\rho` (``td = "linear"``) or the exact
reference derivatives (``td = "exact"``) — is a linear time-invariant system from the
reference and the measurement to the command.  Written as

.. math:: U(s) = F(s)\,R(s) - C(s)\,Y(s),

C is the equivalent feedback controller and F the path from the reference to the command
(with the exact TD, F has one column per supplied derivative :math:`r, \dot r, ...,
r^{(\rho)}`).  The closed loop on a plant P is :math:`Y/R = PF/(1 + PC)`, the noise on the
measurement reaches the command through :math:`-C/(1 + PC)`.  This is the transfer-function
form of Tian & Gao, "Frequency response analysis of active disturbance rejection based
control system", IEEE CCA 2007, and of Herbst, "A simulative study on active disturbance
rejection control (ADRC) as a control tool for practitioners", Electronics 2(3), 2013
(§3, eqs. 10–13: :math:`C_{FB}` and the prefilter), here for any ρ and computed from a
state-space realisation rather than closed-form polynomials.

**Continuous controller.**  With :math:`A` the shift matrix of the chain (6), :math:`B =
e_\rho`, :math:`\beta = (\beta_1..\beta_{\rho+1})` the observer gains,
:math:`k_i = \binom{\rho}{i-1}\omega_c^{\rho-i+1}` (i ≤ m = ``n_feedback``, 0 beyond) and
:math:`g = (k_1..k_\rho, 1)`,

.. math:: \dot z = (A - \beta e_1^T)z + B b_0 u + \beta y,\qquad
          b_0 u = k^T(r_{1..\rho} - z_{1..\rho}) + r^{(\rho)} - z_{\rho+1},

with :math:`r_{1..\rho}, r^{(\rho)}` the prefilter's states and its :math:`\dot r_\rho`
(:func:`aiofl.components.differentiators.linear_prefilter_update`) or the supplied
derivatives.

**Discrete controller** (:mod:`aiofl.engine.kernel.sampled`, one update per sample, the
coefficients of the engine's discrete row :func:`aiofl.engine.sample_time.discrete_row`):
with the predicted state :math:`p_k`, the correction :math:`\hat\xi_k = (I - Le_1^T)p_k +
Ly_k`, the law on :math:`\hat\xi_k` and the prefilter's state at :math:`t_k`, the
prediction :math:`p_{k+1} = \Phi\hat\xi_k + \Gamma u_m + K(y_k - p_{1,k})` with
:math:`u_m = u_k` (or :math:`u_{k-1}` with a one-sample computation delay, a state), the
prefilter :math:`s_{k+1} = \Phi_r s_k + \Gamma_r r_k`.  The output is the command the DAC
applies: :math:`u_k`, or :math:`u_{k-1}` with the delay (so C and F carry its
:math:`z^{-1}`).  Both are affine in the state and the
inputs, so the realisation below is exact; its transfer functions are python-control
``TransferFunction`` objects (discrete ones with ``dt = Ts``).

Saturation is left out (the form holds while :math:`u_{min} < u < u_{max}`).  A
model-assisted observer (``eso.model = "nominal"``), nonlinear ESO, SEF or TD is not LTI and
is refused: its linearisation at an operating point is :mod:`aiofl.analysis.linearize`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from aiofl import layout as L
from aiofl.components.differentiators import linear_prefilter_coefficients
from aiofl.components.feedback import linear_sef_gains
from aiofl.controller import Controller, controller_batch
from aiofl.engine.discrete_rows import Sampling

__all__ = ["TwoDof", "format_two_dof_text", "ladrc_two_dof", "two_dof_closed_loop"]


@dataclass(frozen=True)
class TwoDof:
    r"""The 2-DOF form of a linear ADRC, :math:`u = F r - C y` (module docstring).

    Attributes
    ----------
    feedback
        C, measurement to command with the sign flipped (SISO ``TransferFunction``).
    prefilter
        F, reference input(s) to command (1 × number of reference inputs).
    reference_inputs
        Names of F's inputs: ``("r",)`` with the linear prefilter, ``("r", "r_d1", ...,
        "r_dρ")`` with the exact TD.
    dt
        None (continuous) or the sample time Ts.
    controller
        The controller's realisation, inputs (reference inputs..., y), output u
        (``control.StateSpace``); C and F are its transfer functions.
    label
        What it is, e.g. ``"continuous"`` or ``"sampled at Ts = 0.001 s, ZOH ESO, ..."``.
    feedback_ss
        C's minimal realisation (the ESO and the delay's state; the prefilter's states
        are not driven by y).

    Notes
    -----
    Compute with the realisations: the polynomial coefficients of a discrete C(z), F(z)
    with poles clustered near z = 1 (the ESO's :math:`e^{-\omega_0T_s}` ×(ρ+1), the
    integrator) lose accuracy at low frequency — on a ρ = 3 LADRC at Ts = 1 ms a step
    response through the polynomials was ~1 % off below 1 rad/s, through the realisation
    1e-14 (tests/test_loop_view.py); the continuous ones 1e-6.  The printed factored
    form takes poles and zeros from the realisation (eigenvalues, invariant zeros).
    """

    feedback: Any
    prefilter: Any
    reference_inputs: tuple[str, ...]
    dt: float | None
    controller: Any
    label: str
    feedback_ss: Any = None


def _check_linear(c: Controller) -> None:
    bad = []
    if c.law != "aiofl":
        bad.append(f"law = {c.law!r} (allowed: 'aiofl')")
    if c.eso != "linear":
        bad.append(f"eso = {c.eso!r} (allowed: 'linear')")
    if c.sef != "linear":
        bad.append(f"sef = {c.sef!r} (allowed: 'linear')")
    if c.td not in ("linear", "exact"):
        bad.append(f"td = {c.td!r} (allowed: 'linear', 'exact')")
    if c.eso_model != "none":
        bad.append(f"eso.model = {c.eso_model!r} (allowed: 'none')")
    if bad:
        raise ValueError(
            "the 2-DOF form needs a linear ADRC; this controller has "
            + ", ".join(bad)
            + " (its linearisation at an operating point: aiofl analyze --closed-loop)"
        )


def _pieces(c: Controller) -> dict[str, Any]:
    """Gains of the controller as the engine packs them (Kalman gains resolved)."""
    batch = controller_batch(c)
    f = batch.floats[0]
    rho = c.rho
    w0 = float(f[L.F_OMEGA0])
    alphas = f[L.F_ESO_ALPHA : L.F_ESO_ALPHA + rho + 1]
    betas = np.array([alphas[i] * w0 ** (i + 1) for i in range(rho + 1)])
    m = int(batch.ints[0][L.I_NFB])
    k = linear_sef_gains(rho, float(f[L.F_SEF_OMEGA_C]))
    k[m:] = 0.0
    pf = linear_prefilter_coefficients(rho, float(f[L.F_TD_OMEGA])) if c.td == "linear" else None
    return {"rho": rho, "b0": float(f[L.F_B0]), "betas": betas, "k": k, "pf": pf}


def _prefilter_matrices(pf: NDArray[np.float64]) -> tuple[Any, Any, Any, Any]:
    r"""(A_r, B_r) of the prefilter and (c_s, c_r) of its output
    :math:`\dot r_\rho = c_s^T s + c_r r`."""
    rho = pf.size
    a = np.eye(rho, k=1)
    a[rho - 1, :] = -pf
    b = np.zeros(rho)
    b[rho - 1] = pf[0]
    return a, b, -pf, pf[0]


def _continuous(c: Controller) -> tuple[NDArray[np.float64], ...]:
    """(A, B, C, D) of the continuous controller, inputs (reference inputs, y), output u."""
    p = _pieces(c)
    rho, b0, beta, k = p["rho"], p["b0"], p["betas"], p["k"]
    n1 = rho + 1
    g = np.append(k, 1.0)
    nr = 1 if c.td == "linear" else rho + 1
    ns = rho if c.td == "linear" else 0
    nx = n1 + ns
    # u = cu x + du [r_inputs, y]
    cu = np.zeros(nx)
    du = np.zeros(nr + 1)
    cu[:n1] = -g / b0
    a = np.zeros((nx, nx))
    b = np.zeros((nx, nr + 1))
    if c.td == "linear":
        ar, br, cs, cr = _prefilter_matrices(p["pf"])
        cu[n1:] = (k + cs) / b0
        du[0] = cr / b0
        a[n1:, n1:] = ar
        b[n1:, 0] = br
    else:
        du[:rho] = k / b0
        du[rho] = 1.0 / b0
    a[:n1, :n1] = np.eye(n1, k=1) - np.outer(beta, np.eye(1, n1))
    b[:n1, nr] = beta
    a[rho - 1, :] += b0 * cu
    b[rho - 1, :] += b0 * du
    return a, b, cu[None, :], du[None, :]


def _discrete(c: Controller, sampling: Sampling) -> tuple[NDArray[np.float64], ...]:
    """(A, B, C, D) of the engine's discrete controller (module docstring)."""
    from aiofl.engine import discrete_rows as DS
    from aiofl.engine.sample_time import discrete_row

    sampling.check(c)
    row = discrete_row(c, sampling, None)
    p = _pieces(c)
    rho, b0, k = p["rho"], p["b0"], p["k"]
    n1 = rho + 1
    phi = np.eye(n1) + np.array(
        [row[DS.D_PHI + i * DS.STRIDE : DS.D_PHI + i * DS.STRIDE + n1] for i in range(n1)]
    )
    gam = row[DS.D_GAM : DS.D_GAM + n1]
    kk = row[DS.D_K : DS.D_K + n1]
    ll = row[DS.D_L : DS.D_L + n1]
    g = np.append(k, 1.0)
    nr = 1 if c.td == "linear" else rho + 1
    ns = rho if c.td == "linear" else 0
    nd = 1 if sampling.delay else 0
    nx = n1 + ns + nd
    e1 = np.eye(1, n1)[0]
    mcorr = np.eye(n1) - np.outer(ll, e1)  # ξ̂ = mcorr p + l y
    # u = cu x + du [r_inputs, y]
    cu = np.zeros(nx)
    du = np.zeros(nr + 1)
    cu[:n1] = -(g @ mcorr) / b0
    du[nr] = -(g @ ll) / b0
    a = np.zeros((nx, nx))
    b = np.zeros((nx, nr + 1))
    if c.td == "linear":
        _, _, cs, cr = _prefilter_matrices(p["pf"])
        cu[n1 : n1 + ns] = (k + cs) / b0
        du[0] = cr / b0
        pf_phi = np.eye(rho) + np.array(
            [
                row[DS.D_PF_PHI + i * DS.PF_STRIDE : DS.D_PF_PHI + i * DS.PF_STRIDE + rho]
                for i in range(rho)
            ]
        )
        a[n1 : n1 + ns, n1 : n1 + ns] = pf_phi
        b[n1 : n1 + ns, 0] = row[DS.D_PF_GAM : DS.D_PF_GAM + rho]
    else:
        du[:rho] = k / b0
        du[rho] = 1.0 / b0
    # p+ = Φ(mcorr p + l y) + Γ u_m + K (y - p_1)
    a[:n1, :n1] = phi @ mcorr - np.outer(kk, e1)
    b[:n1, nr] = phi @ ll + kk
    if nd:  # the state keeps u_k; the DAC applies it (and the ESO uses it) at k + 1
        a[:n1, nx - 1] += gam
        a[nx - 1, :] = cu
        b[nx - 1, :] = du
        cu, du = np.eye(1, nx)[0, ::-1].copy(), np.zeros(nr + 1)
    else:
        a[:n1, :] += np.outer(gam, cu)
        b[:n1, :] += np.outer(gam, du)
    return a, b, cu[None, :], du[None, :]


def _siso_tf(
    a: NDArray[np.float64], b: NDArray[np.float64], c: Any, d: float, dt: float | None
) -> Any:
    r"""``TransferFunction`` of :math:`c(sI-a)^{-1}b + d` from characteristic polynomials:
    :math:`\mathrm{den} = \det(sI - a)`, :math:`\mathrm{num} = (\det(sI - a + \gamma bc) -
    \mathrm{den})/\gamma + d\,\mathrm{den}` (the matrix determinant lemma), a balanced
    first (:func:`scipy.linalg.matrix_balance`), :math:`\gamma` scaling :math:`bc` to
    :math:`\|a\|`: each polynomial is that of a nearby matrix (backward stable), where
    :func:`control.ss2tf` lost 1e-10 of the continuous controller's response."""
    import control
    from scipy.linalg import matrix_balance

    ab, (sc, _) = matrix_balance(a, separate=True, permute=False)
    bb = np.asarray(b, dtype=np.float64).reshape(-1) / sc
    cb = np.asarray(c, dtype=np.float64).reshape(-1) * sc
    den = np.poly(ab).real
    bc = np.outer(bb, cb)
    nbc = float(np.linalg.norm(bc, 2))
    gamma = max(float(np.linalg.norm(ab, 2)), 1.0) / nbc if nbc > 0 else 1.0
    num = (np.poly(ab - gamma * bc).real - den) / gamma + float(d) * den
    # the leading coefficients are the Markov parameters d, cb, cab, ...: zero those that
    # vanish (the subtraction leaves rounding there, a spurious huge zero)
    if float(d) == 0.0:
        num[0] = 0.0
        v, scale = bb.copy(), float(np.linalg.norm(bb))
        na = float(np.linalg.norm(ab, 2))
        for j in range(1, num.size):
            if abs(float(cb @ v)) > 1e-10 * float(np.linalg.norm(cb)) * scale:
                break
            num[j] = 0.0
            v, scale = ab @ v, scale * na
    return control.tf(num, den, dt if dt is not None else 0)


def ladrc_two_dof(controller: Controller, sampling: Sampling | None = None) -> TwoDof:
    r"""The 2-DOF form :math:`u = F r - C y` of a linear ADRC (module docstring).

    Parameters
    ----------
    controller
        A linear ADRC: ``eso = "linear"`` (bandwidth or Kalman gains), ``sef = "linear"``,
        ``law = "aiofl"``, ``td = "linear"`` or ``"exact"``, ``eso.model = "none"``.
    sampling
        None for the continuous controller; a :class:`~aiofl.engine.discrete_rows.Sampling`
        for the engine's discrete one (ESO by ZOH or Euler as configured, the prefilter
        by ZOH, the computation delay).

    Returns
    -------
    TwoDof
        C and F as python-control ``TransferFunction`` objects (``dt = Ts`` when sampled).

    Raises
    ------
    ValueError
        For a controller that is not a linear ADRC (naming the offending fields).
    """
    import control

    _check_linear(controller)
    rho = controller.rho
    refs = ("r",) if controller.td == "linear" else ("r", *(f"r_d{i}" for i in range(1, rho + 1)))
    if sampling is None:
        a, b, c, d = _continuous(controller)
        dt: float | None = None
        label = "continuous"
    else:
        a, b, c, d = _discrete(controller, sampling)
        dt = float(sampling.ts)
        eso = sampling.eso_method(controller)
        label = (
            f"sampled at Ts = {sampling.ts:g} s: ESO by {eso.upper() if eso == 'zoh' else eso}"
            + (", prefilter by ZOH" if controller.td == "linear" else "")
            + f", {sampling.delay}-sample computation delay"
        )
    sys = control.ss(a, b, c, d, dt if dt is not None else 0, inputs=[*refs, "y"], outputs=["u"])
    nr = len(refs)
    # C's minimal part: the prefilter's states are not driven by y
    keep = np.ones(a.shape[0], dtype=bool)
    if controller.td == "linear":
        keep[rho + 1 : 2 * rho + 1] = False
    fb_ss = control.ss(
        a[np.ix_(keep, keep)], b[keep, nr], -c[:, keep], -d[0, nr], dt if dt is not None else 0
    )
    fb = _siso_tf(fb_ss.A, fb_ss.B, fb_ss.C, float(fb_ss.D[0, 0]), dt)
    cols = [_siso_tf(a, b[:, j], c, d[0, j], dt) for j in range(nr)]
    pf = cols[0] if nr == 1 else control.combine_tf([cols])
    return TwoDof(
        feedback=fb,
        prefilter=pf,
        reference_inputs=refs,
        dt=dt,
        controller=sys,
        label=label,
        feedback_ss=fb_ss,
    )


def two_dof_closed_loop(form: TwoDof, plant: Any) -> Any:
    r"""The closed loop of ``form`` on a linear ``plant`` (python-control system, u → y,
    continuous, or discrete with the same dt), as a state-space system from the reference
    input(s) to (y, u): :math:`y = PF/(1+PC)\,r`, :math:`u = F/(1+PC)\,r`.  Built from the
    controller's realisation (:attr:`TwoDof.controller`), not from the polynomials."""
    import control

    k = form.controller
    nr = len(form.reference_inputs)
    p = control.ss(plant)
    # interconnect: plant input u, controller input (r, y)
    ak, bk, ck, dk = (np.asarray(m, dtype=np.float64) for m in (k.A, k.B, k.C, k.D))
    ap, bp, cp, dp = (np.asarray(m, dtype=np.float64) for m in (p.A, p.B, p.C, p.D))
    if np.any(dp != 0.0):
        raise ValueError("the plant has a direct term u → y; allowed: a strictly proper plant")
    bkr, bky = bk[:, :nr], bk[:, nr:]
    dkr, dky = dk[:, :nr], dk[:, nr:]
    cu = np.hstack([dky @ cp, ck])  # u = ck xk + dkr r + dky cp xp
    du = dkr
    np_, nk = ap.shape[0], ak.shape[0]
    a = np.zeros((np_ + nk, np_ + nk))
    a[:np_, :np_] = ap
    a[:np_, :] += bp @ cu
    a[np_:, :np_] = bky @ cp
    a[np_:, np_:] = ak
    b = np.vstack([bp @ du, bkr])
    c = np.vstack([np.hstack([cp, np.zeros((1, nk))]), cu])
    d = np.vstack([np.zeros_like(du), du])
    return control.ss(a, b, c, d, k.dt, inputs=list(form.reference_inputs), outputs=["y", "u"])


def _roots_text(roots: NDArray[np.complex128], var: str) -> str:
    """``(s + 40)^4 (s^2 + 2·0.5·8 s + 64)``-like factors, one per real root or pair."""
    parts: list[str] = []
    r = np.asarray(roots, dtype=np.complex128)
    for v in sorted(r[np.abs(r.imag) <= 1e-9 * np.maximum(1.0, np.abs(r))], key=lambda z: z.real):
        x = v.real
        parts.append(var if abs(x) < 1e-9 else f"({var} {'−' if x > 0 else '+'} {abs(x):.6g})")
    for v in sorted(r[r.imag > 1e-9 * np.maximum(1.0, np.abs(r))], key=lambda z: z.real):
        parts.append(
            f"({var}² {'−' if v.real > 0 else '+'} {abs(2 * v.real):.6g} {var} + {abs(v) ** 2:.6g})"
        )
    return " ".join(parts) or "1"


def _zpk_text(sys: Any, var: str) -> str:
    """Gain, zeros and poles of a SISO realisation in factored form: poles the eigenvalues,
    zeros the invariant zeros (finite generalised eigenvalues of the Rosenbrock pencil),
    gain matched at one point away from both (the coefficients of a z-polynomial hide
    poles clustered near z = 1)."""
    poles = np.linalg.eigvals(np.asarray(sys.A, dtype=np.float64))
    from scipy.linalg import eigvals

    a, b, c, d = (
        np.atleast_2d(np.asarray(m, dtype=np.float64)) for m in (sys.A, sys.B, sys.C, sys.D)
    )
    n = a.shape[0]
    pencil = np.block([[a, b], [c, d]])
    e = np.zeros_like(pencil)
    e[:n, :n] = np.eye(n)
    zeros = eigvals(pencil, e)  # invariant zeros: the finite generalised eigenvalues
    zeros = zeros[np.isfinite(zeros)]
    # a relative degree r leaves r infinite zeros, which rounding puts at huge finite values
    # (±1e5 for r = 4): keep the n - r smallest, n - r the numerator's degree
    num = np.trim_zeros(np.asarray(_siso_tf(a, b[:, 0], c, float(d[0, 0]), None).num[0][0]), "f")
    zeros = zeros[np.argsort(np.abs(zeros))][: max(num.size - 1, 0)]
    big = 10.0 * max(1.0, float(np.max(np.abs(np.r_[poles, zeros]), initial=1.0)))
    x0 = complex(0.3, 1.7) * big if var == "s" else complex(-1.3, 0.45)
    h = complex(np.asarray(sys(x0)).ravel()[0])
    if h == 0.0:
        return "0"
    gain = h * np.prod(x0 - poles) / np.prod(x0 - zeros)
    text = f"{gain.real:.6g} · {_roots_text(zeros, var)} / {_roots_text(poles, var)}"
    # self-check against the realisation at frequencies across its poles: an ill-scaled
    # realisation (‖A‖ ~ 1e16 for a ρ = 4 design with b0 ~ 3e4) gives zeros that are not
    mags = np.abs(poles[np.abs(poles) > 0]) if var == "s" else np.array([0.3, 1.0, 3.0])
    ws = (
        np.geomspace(max(float(mags.min()), 1e-6) / 3, float(mags.max()) * 3, 7)
        if mags.size
        else [1.0]
    )
    pts = 1j * np.asarray(ws) if var == "s" else np.exp(1j * np.geomspace(1e-2, 3.0, 7))
    ref = np.array([complex(np.asarray(sys(x)).ravel()[0]) for x in pts])
    fz = np.array([gain * np.prod(x - zeros) / np.prod(x - poles) for x in pts])
    err = float(np.max(np.abs(fz - ref) / np.maximum(np.abs(ref), 1e-300)))
    if not err <= 1e-3:
        text += f"  [factored form off by up to {err:.2g} (relative) on this realisation]"
    return text


def format_two_dof_text(forms: list[TwoDof]) -> list[str]:
    """Text lines: C and F of each form (``aiofl analyze --two-dof``)."""
    out = ["LADRC as a 2-DOF controller, u = F·r − C·y (Tian & Gao 2007; Herbst 2013):"]
    for f in forms:
        var = "s" if f.dt is None else "z"
        out.append(f"  {f.label}:")
        out.append(f"    C({var}) = {_zpk_text(f.feedback_ss, var)}")
        nr = len(f.reference_inputs)
        for j, name in enumerate(f.reference_inputs):
            tag = "F" if nr == 1 else f"F_{name}"
            out.append(f"    {tag}({var}) = {_zpk_text(f.controller[0, j], var)}")
    return out
