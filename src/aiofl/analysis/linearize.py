r"""Linearisation of the whole closed loop (plant + TD + ESO + SEF + law) and its stability.

The closed loop of :mod:`aiofl.engine.kernel.continuous` is an ODE
:math:`\dot z = F(z; r, \tau_d, n)`.  :class:`aiofl.analysis.closed_loop.ClosedLoop` writes
the same equations in Python (checked against the engine in the tests); this module finds
the operating point :math:`z^*` with the reference held at a constant :math:`r^*` and the
disturbance at its final value (:func:`scipy.optimize.root`, scaled), and takes the
Jacobians exactly, from the compiled loop (:mod:`aiofl.analysis.compiled_loop`: forward
mode, the plant's Jacobians by complex-step differentiation, :mod:`aiofl.analysis.derivatives`),

.. math:: A = \frac{\partial F}{\partial z}(z^*),\qquad
          \dot{\delta z} = A\,\delta z + B\,(\delta r, \delta\tau_d, \delta n),\quad
          (\delta y, \delta u) = C\,\delta z + D\,(\delta r, \delta\tau_d, \delta n).

With the exact reference profile (``td = "exact"``) the loop is driven by r *and* its
derivatives :math:`r^{(1)}..r^{(\rho)}`, which are inputs of their own (``r_d1..``);
:meth:`Linearization.tracking_statespace` folds them into the single input r.

The verdict is *stable* if every eigenvalue of A has a negative real part, *unstable* if
one has a positive real part, *marginal* otherwise (within a relative tolerance).

**Repeated eigenvalues.**  A k-fold defective eigenvalue (a Jordan block: Gao's
bandwidth tuning puts ρ+1 observer poles on −ω0) is computed by any eigenvalue routine
only to :math:`O(\epsilon^{1/k})`: a cluster of k values (for Gao's LADRC with ρ = 4 on a
chain of integrators the five poles at −50 come out up to 0.1 apart, from an exact A).
The *mean* of the cluster is well-conditioned, :math:`O(\epsilon)` (Kato, *Perturbation
Theory for Linear Operators*, ch. II §1: the weighted mean of the λ-group is analytic in
the perturbation where its members have branch points).  :func:`group_eigenvalues` finds
such clusters — eigenvalues whose distances are within how far they move when A is
perturbed at 10 × rounding level, their own accuracy — and reports each as its mean
with a multiplicity, so −50 ×3 prints as −50 ×3.  Eigenvalues that rounding cannot
have made differ are not merged (two simple eigenvalues 1e-6 apart stay two; −10 ×3
and −10.1 ×2 stay two groups; see the tests).

Frequency-domain margins (the loop broken at the plant input) are
:mod:`aiofl.analysis.frequency`; the closed loop itself, and how its non-smooth elements
are linearised, is :mod:`aiofl.analysis.closed_loop`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from aiofl.analysis.closed_loop import DEFAULT_AMPLITUDE, ClosedLoop
from aiofl.analysis.frequency import LoopMargins, loop_margins, loop_transfer
from aiofl.components.observers import eso_error_matrix, eso_gains
from aiofl.controller import Controller
from aiofl.plants.base import Plant
from aiofl.scenario import Scenario

__all__ = [
    "SWEEP_AMPLITUDES",
    "Linearization",
    "closed_loop_verdict",
    "eso_statespace",
    "format_linearization_text",
    "group_eigenvalues",
    "linear_eso_statespace",
    "linearize_closed_loop",
]

SWEEP_AMPLITUDES = (1e-4, 1e-3, 1e-2, 1e-1)
"""Amplitudes for ``verdicts_by_amplitude`` when the verdict may depend on ε."""


# ------------------------------------------------------------ repeated eigenvalues
def group_eigenvalues(
    a: ArrayLike, *, trials: int = 4, level: float = 10.0, seed: int = 0
) -> tuple[tuple[complex, int], ...]:
    r"""Eigenvalues of A with numerically repeated ones merged: ``((λ, multiplicity), ...)``.

    A is balanced (:func:`scipy.linalg.matrix_balance`) and its eigenvalues computed; then
    ``trials`` seeded perturbations :math:`A + E`, :math:`\|E\|_2 = \text{level}\cdot
    \epsilon\,\|A\|_2`, give how far each eigenvalue :math:`\lambda_i` moves,
    :math:`s_i` (eigenvalues matched by :func:`scipy.optimize.linear_sum_assignment`).
    :math:`\lambda_i` and :math:`\lambda_j` belong to one group when
    :math:`|\lambda_i - \lambda_j| \le 2(s_i + s_j)`: rounding alone could have made them
    differ.  A group is reported as its mean (well-conditioned where its members are not;
    module docstring), real when the group is closed under conjugation.  Sorted by
    decreasing real part.

    The level, 10 by default, is that of the backward error of the QR algorithm
    (:math:`p(n)\,\epsilon\|A\|` with a modest :math:`p(n)`; Golub & Van Loan, *Matrix
    Computations*, 4th ed., §7.5.6), so :math:`s_i` estimates the accuracy the computed
    :math:`\lambda_i` actually has — for a k-fold defective eigenvalue
    :math:`(10\,\epsilon\|A\|)^{1/k}` up to constants, the radius of its computed cluster
    times :math:`10^{1/k}`.  First-order condition numbers :math:`\kappa_i =
    \|y_i\|\|x_i\|/|y_i^Hx_i|` (left and right eigenvectors) do not serve: at a Jordan
    block they are infinite in exact arithmetic and ~1e12 in floating point, which would
    merge anything.  Two groups closer than their accuracy cannot be told apart and are
    merged: for the LADRC with ρ = 2 on ÿ = bu, ω0 = 10 and ω_c = 10.1 (−10 ×3, −10.1 ×2)
    are two groups, ω_c = 10.01 merges into one of multiplicity 5 (the computed eigenvalues
    of the two blocks are ~1e-2 apart from their true values there).  An earlier level of
    1000 merged ω_c = 10.1 too.

    Parameters
    ----------
    a
        The square matrix A.
    trials, level, seed
        The perturbations made, their size in units of ε‖A‖₂ and their random seed.

    Returns
    -------
    tuple of (complex, int)
    """
    from scipy.linalg import eigvals, matrix_balance
    from scipy.optimize import linear_sum_assignment

    a = np.asarray(a, dtype=np.float64)
    n = a.shape[0]
    if n == 0:
        return ()
    bal, _ = matrix_balance(a, permute=False)
    lam = eigvals(bal)
    if not np.all(np.isfinite(lam)):
        return tuple((complex(v), 1) for v in lam)
    rng = np.random.default_rng(seed)
    size = level * np.finfo(np.float64).eps * np.linalg.norm(bal, 2)
    move = np.zeros(n)
    for _ in range(trials):
        e = rng.standard_normal((n, n))
        mu = eigvals(bal + size * e / np.linalg.norm(e, 2))
        dist = np.abs(lam[:, None] - mu[None, :])
        rows, cols = linear_sum_assignment(dist)
        move[rows] = np.maximum(move[rows], dist[rows, cols])
    parent = list(range(n))

    def find(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for i in range(n):
        for j in range(i + 1, n):
            if abs(lam[i] - lam[j]) <= 2.0 * (move[i] + move[j]):
                parent[find(i)] = find(j)
    groups: dict[int, list[int]] = {}
    for i in range(n):
        groups.setdefault(find(i), []).append(i)
    out = []
    for members in groups.values():
        vals = lam[members]
        mean = complex(vals.mean())
        if len(members) > 1:
            conj = np.sort_complex(np.conj(vals))
            if np.allclose(
                np.sort_complex(vals), conj, rtol=0, atol=4 * float(move[members].max())
            ):
                mean = complex(mean.real, 0.0)
        out.append((mean, len(members)))
    out.sort(key=lambda g: (-g[0].real, g[0].imag))
    return tuple(out)


# ------------------------------------------------------------------ linearisation
@dataclass(frozen=True)
class Linearization:
    """The closed loop linearised at its operating point.

    Attributes
    ----------
    a, b, c, d
        State-space matrices; inputs :attr:`input_names` (reference r, with the exact TD
        its derivatives ``r_d1..r_dρ``, disturbance d, measurement noise n), outputs
        ``(y, u)``.
    state_names
        Names of the states (see :class:`ClosedLoop`).
    z_op, r_op, d_op
        Operating point.
    eigenvalues
        Eigenvalues of ``a`` (numerically repeated ones as their group's mean, repeated),
        sorted by decreasing real part.
    amplitude
        Error amplitude ε of the secant gains.
    notes
        How each non-smooth element was handled, and other remarks.
    input_names
        Names of the columns of ``b`` and ``d``.
    eigenvalue_groups
        ``((λ, multiplicity), ...)`` (:func:`group_eigenvalues`).
    loop
        ``(A, B, C, D)`` of the loop broken at the plant input (input the plant's
        :math:`u_p`, output the controller's u), for :mod:`aiofl.analysis.frequency`.
    """

    a: NDArray[np.float64]
    b: NDArray[np.float64]
    c: NDArray[np.float64]
    d: NDArray[np.float64]
    state_names: tuple[str, ...]
    z_op: NDArray[np.float64]
    r_op: float
    d_op: float
    eigenvalues: NDArray[np.complex128]
    amplitude: float
    notes: tuple[str, ...]
    input_names: tuple[str, ...] = ("r", "d", "n")
    eigenvalue_groups: tuple[tuple[complex, int], ...] = ()
    loop: tuple[NDArray[np.float64], ...] = field(default=(), repr=False)

    output_names = ("y", "u")

    @property
    def max_real(self) -> float:
        """Largest real part of the eigenvalues."""
        return float(self.eigenvalues.real.max())

    def verdict(self, rtol: float = 1e-6) -> str:
        """``"stable"``, ``"unstable"`` or ``"marginal"`` (abs(max Re λ) ≤ rtol·max abs(λ))."""
        return _verdict(self.eigenvalues, rtol)

    @property
    def slowest(self) -> complex:
        """The eigenvalue with the largest real part (slowest / least damped mode)."""
        return complex(self.eigenvalues[0])

    @property
    def fastest(self) -> complex:
        """The eigenvalue with the most negative real part."""
        return complex(self.eigenvalues[-1])

    @property
    def n_reference_inputs(self) -> int:
        """1, or ρ+1 with the exact TD (r and its derivatives are the first inputs)."""
        return sum(1 for k in self.input_names if k == "r" or k.startswith("r_d"))

    def statespace(self) -> Any:
        """The linearised loop as a ``control.StateSpace`` (python-control), inputs
        :attr:`input_names`, outputs (y, u)."""
        import control

        return control.ss(
            self.a,
            self.b,
            self.c,
            self.d,
            states=list(self.state_names),
            inputs=list(self.input_names),
            outputs=list(self.output_names),
        )

    def tracking_statespace(self) -> Any:
        r"""The reference-to-output model r → y as a SISO ``control.StateSpace``.

        With the exact TD the loop sees :math:`r^{(k)}`, k = 0..ρ, through columns
        :math:`B_k`, :math:`D_k`, so :math:`Y(s) = \sum_k s^k [C_y(sI-A)^{-1}B_k + D_{y,k}]R(s)`.
        With :math:`s^k(sI-A)^{-1} = A^k(sI-A)^{-1} + \sum_{j<k} s^{k-1-j}A^j` this is

        .. math:: \frac{Y}{R}(s) = C_y(sI-A)^{-1}\tilde B + \tilde D,\quad
                  \tilde B = \sum_k A^k B_k,\quad
                  \tilde D = D_{y,0} + \sum_{k\ge1} C_y A^{k-1} B_k,

        provided the polynomial part vanishes, :math:`D_{y,m} + \sum_{k>m} C_y A^{k-1-m}B_k
        = 0` for m ≥ 1 — true when y does not react to :math:`r^{(m)}` faster than the plant's
        relative degree allows, which is checked.  (r → u is improper under the exact TD —
        u holds :math:`r^{(\rho)}/b_0` — so it has no state-space model of r alone; use
        :meth:`reference_response`.)

        Raises
        ------
        ValueError
            When the polynomial part does not vanish.
        """
        import control

        nr = self.n_reference_inputs
        a, cy = self.a, self.c[:1]
        bks = [self.b[:, [k]] for k in range(nr)]
        dks = [self.d[:1, [k]] for k in range(nr)]
        b_t = np.zeros_like(bks[0])
        for bk in reversed(bks):  # Horner: B0 + A(B1 + A(B2 + ...))
            b_t = bk + a @ b_t
        d_t = dks[0].copy()
        # Markov terms C A^j B_k
        for m in range(1, nr):
            coeff, size = dks[m].copy(), np.abs(dks[m]).copy()
            for k in range(m + 1, nr):
                term = cy @ np.linalg.matrix_power(a, k - 1 - m) @ bks[k]
                coeff += term
                size += np.abs(term)
            if np.any(np.abs(coeff) > 1e-8 * size + 1e-300):
                raise ValueError(
                    f"r → y holds r's derivative of order {m} directly (coefficient "
                    f"{float(coeff.ravel()[0]):.3g}); it has no proper state-space model"
                )
        for k in range(1, nr):
            d_t = d_t + cy @ np.linalg.matrix_power(a, k - 1) @ bks[k]
        return control.ss(
            a, b_t, cy, d_t, states=list(self.state_names), inputs=["r"], outputs=["y"]
        )

    def reference_response(self, omega: ArrayLike) -> NDArray[np.complex128]:
        r"""Frequency response of (y, u) to :math:`r = e^{j\omega t}` with its derivatives
        :math:`r^{(k)} = (j\omega)^k r` (exact TD) fed forward: shape (2, len(ω)).

        :math:`\sum_k (j\omega)^k [C(j\omega I - A)^{-1}B_k + D_k]`, one linear solve per
        frequency (an independent check of :meth:`tracking_statespace`)."""
        w = np.atleast_1d(np.asarray(omega, dtype=np.float64))
        nr, n = self.n_reference_inputs, self.a.shape[0]
        out = np.empty((2, w.size), dtype=np.complex128)
        for i, wi in enumerate(w):
            s = 1j * wi
            powers = s ** np.arange(nr)
            bw = self.b[:, :nr] @ powers
            dw = self.d[:, :nr] @ powers
            out[:, i] = self.c @ np.linalg.solve(s * np.eye(n) - self.a, bw) + dw
        return out

    def loop_transfer(self) -> Any:
        r"""The loop transfer function :math:`L(s)` at the plant input as a
        ``control.StateSpace`` (:func:`aiofl.analysis.frequency.loop_transfer`)."""
        return loop_transfer(*self.loop)

    @cached_property
    def margins(self) -> LoopMargins:
        """Gain, phase, delay margins, :math:`M_s` and least damping
        (:func:`aiofl.analysis.frequency.loop_margins`)."""
        return loop_margins(self.loop_transfer(), self.eigenvalues)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (``verdict``, ``eigenvalues`` as [[re, im], ...], the margins
        ``gain_margin_db``, ``phase_margin_deg``, ``delay_margin_s``, ``ms``,
        ``min_damping``, ...)."""
        out = {
            "verdict": self.verdict(),
            "eigenvalues": [[float(z.real), float(z.imag)] for z in self.eigenvalues],
            "eigenvalue_groups": [
                {"value": [lam.real, lam.imag], "multiplicity": k}
                for lam, k in self.eigenvalue_groups
            ],
            "max_real": self.max_real,
            "slowest": [self.slowest.real, self.slowest.imag],
            "fastest": [self.fastest.real, self.fastest.imag],
            "states": list(self.state_names),
            "operating_point": {
                "r": self.r_op,
                "d": self.d_op,
                "z": [float(v) for v in self.z_op],
            },
            "amplitude": self.amplitude,
            "notes": list(self.notes),
        }
        out.update(self.margins.to_dict())
        return out


def _verdict(eig: NDArray[np.complex128], rtol: float = 1e-6) -> str:
    scale = max(1.0, float(np.max(np.abs(eig))))
    mx = float(eig.real.max())
    if mx < -rtol * scale:
        return "stable"
    if mx > rtol * scale:
        return "unstable"
    return "marginal"


def linearize_closed_loop(
    config: Any = None,
    *,
    plant: Plant | None = None,
    controller: Controller | None = None,
    scenario: Scenario | None = None,
    amplitude: float = DEFAULT_AMPLITUDE,
    r_op: float | None = None,
) -> Linearization:
    r"""Linearise the closed loop of a run config (or plant, controller, scenario).

    Parameters
    ----------
    config
        A :class:`aiofl.config.RunConfig`, a preset name or a config path (or None with
        ``plant``, ``controller``, ``scenario``).
    plant, controller, scenario
        The loop's parts when ``config`` is None (all three needed).
    amplitude
        Error amplitude ε for the secant gains of fal / g(e) / INLSEF (module docstring of
        :mod:`aiofl.analysis.closed_loop`).
    r_op
        Reference value to hold (default:
        :func:`aiofl.analysis.closed_loop.reference_operating_value`).

    Returns
    -------
    Linearization
    """
    if config is not None:
        if isinstance(config, str) or hasattr(config, "__fspath__"):
            from aiofl.config import load_config

            config = load_config(config)
        plant, controller, scenario = config.plant, config.controller, config.scenario
    if plant is None or controller is None or scenario is None:
        raise ValueError("give a run config, or plant, controller and scenario")
    loop = ClosedLoop(plant, controller, scenario, mode="linearise", amplitude=amplitude)
    if r_op is not None:
        loop.r_op = float(r_op)
    z = loop.operating_point()
    a, b, c, d = loop.linear_model(z)
    broken = loop.linear_model(z, broken=True)
    groups = group_eigenvalues(a)
    eig = np.array([lam for lam, k in groups for _ in range(k)], dtype=np.complex128)
    notes = list(loop.nonsmooth)
    if controller.law == "iofl":
        notes.append("IOFL law: the ESO is integrated but not used; its poles do not interact")
    if scenario.noise_variance > 0:
        notes.append("measurement noise set to 0 at the operating point (it is an input n)")
    notes += loop.derivatives.notes
    return Linearization(
        a=a,
        b=b,
        c=c,
        d=d,
        state_names=loop.state_names,
        z_op=z,
        r_op=loop.r_op,
        d_op=loop.d_op,
        eigenvalues=eig,
        amplitude=float(amplitude),
        notes=tuple(notes),
        input_names=loop.input_names,
        eigenvalue_groups=groups,
        loop=broken,
    )


def _depends_on_amplitude(controller: Controller) -> bool:
    c = controller
    if c.law != "aiofl":
        return False
    if c.eso == "improved" and c.value("eso.g_alpha") != 1.0:
        return True
    if c.sef == "improved":
        return True
    if c.sef == "nonlinear":
        return any(
            c.value(f"sef.alpha{i}") != 1.0 for i in range(1, c.n_feedback + 1)
        )  # fal is linear only for ε ≤ δ
    return False


def closed_loop_verdict(
    run_config: Any, amplitude: float = DEFAULT_AMPLITUDE, linearization: Any = None
) -> dict[str, Any]:
    """Stability verdict, damping and margins of a run config's linearised closed loop.

    Parameters
    ----------
    run_config
        A :class:`~aiofl.config.RunConfig` or a config path / preset name.
    amplitude, linearization
        ε of :func:`linearize_closed_loop`; a result of it at ``amplitude`` (the default
        operating point) to reuse instead of computing it again.

    Returns
    -------
    dict
        ``{"verdict": "stable"|"unstable"|"marginal", "eigenvalues": [[re, im], ...],
        "max_real", "slowest", "fastest", "states", "operating_point", "amplitude",
        "notes"}``; ``"min_damping"`` (least ζ of the eigenvalues) and the margins of the
        loop broken at the plant input, ``"gain_margin_db"``, ``"phase_margin_deg"``,
        ``"delay_margin_s"``, ``"ms"`` (None where undefined or infinite,
        ``"margin_notes"`` says which; :mod:`aiofl.analysis.frequency`); and, when the
        secant gains depend on ε, ``"verdicts_by_amplitude"`` (ε -> verdict over
        :data:`SWEEP_AMPLITUDES`).
    """
    cfg = run_config
    if isinstance(cfg, str) or hasattr(cfg, "__fspath__"):
        from aiofl.config import load_config

        cfg = load_config(cfg)
    lin = linearization or linearize_closed_loop(cfg, amplitude=amplitude)
    out = lin.to_dict()
    if _depends_on_amplitude(cfg.controller):
        sweep = {}
        for eps in SWEEP_AMPLITUDES:
            try:
                sweep[f"{eps:g}"] = linearize_closed_loop(cfg, amplitude=eps).verdict()
            except ValueError as exc:
                sweep[f"{eps:g}"] = f"no operating point: {exc}"
        out["verdicts_by_amplitude"] = sweep
    return out


# ----------------------------------------------------------- python-control interop
def linear_eso_statespace(rho: int, omega0: float, alphas: Sequence[float], b0: float) -> Any:
    r"""The linear ESO (5)/(16) as a ``control.StateSpace`` with inputs (u, y).

    .. math:: \dot{\hat\xi} = (A - LC)\hat\xi + b_0 e_\rho u + L y,\qquad
              L = (\beta_1..\beta_{\rho+1}),\ \beta_i = \alpha_i\omega_0^i

    Outputs are the ρ+1 estimates; the eigenvalues of A − LC are the roots of
    :math:`s^{\rho+1} + \beta_1 s^\rho + \dots + \beta_{\rho+1}`.

    Parameters
    ----------
    rho, omega0, alphas, b0
        ρ, ω₀ [rad/s], the ρ + 1 coefficients α and the input gain b₀.

    Returns
    -------
    control.StateSpace
    """
    import control

    if len(alphas) != rho + 1:
        raise ValueError(f"alphas has {len(alphas)} entries; rho + 1 = {rho + 1} needed")
    betas = eso_gains(omega0, alphas)
    a = eso_error_matrix(betas)
    b = np.zeros((rho + 1, 2))
    b[rho - 1, 0] = b0
    b[:, 1] = betas
    names = [f"xi_hat{i}" for i in range(1, rho + 2)]
    return control.ss(
        a,
        b,
        np.eye(rho + 1),
        np.zeros((rho + 1, 2)),
        inputs=["u", "y"],
        outputs=names,
        states=names,
    )


def eso_statespace(controller: Controller) -> Any:
    """The (linear) ESO of a controller as a ``control.StateSpace`` (inputs u, y)."""
    if controller.eso != "linear":
        raise ValueError("eso_statespace: only the linear ESO is a linear system (eso = 'linear')")
    c = controller
    alphas = [c.value(f"eso.alpha{i}") for i in range(1, c.rho + 2)]
    return linear_eso_statespace(c.rho, c.value("eso.omega0"), alphas, c.value("law.b0"))


# ---------------------------------------------------------------------- formatting
def _fmt(z: complex) -> str:
    if abs(z.imag) < 1e-9 * max(1.0, abs(z.real)):
        return f"{z.real:.6g}"
    return f"{z.real:.6g} {'+' if z.imag >= 0 else '−'} {abs(z.imag):.6g}j"


def _fmt_margin(value: float | None, unit: str, none: str) -> str:
    if value is None or not np.isfinite(value):
        return none
    return f"{value:.4g}{unit}"


def format_margins_text(lin: Linearization) -> list[str]:
    """Text lines for the damping and the margins (:mod:`aiofl.analysis.frequency`)."""
    m = lin.margins
    out = []
    if m.min_damping is not None and m.least_damped is not None:
        out.append(f"  least damping: ζ = {m.min_damping:.4g} (λ = {_fmt(m.least_damped)})")
    gm = _fmt_margin(m.gain_margin_db, " dB", "∞ (no phase crossover)")
    if np.isfinite(m.phase_crossover):
        gm += f" at {m.phase_crossover:.4g} rad/s"
    pm = _fmt_margin(m.phase_margin_deg, "°", "∞ (|L| never crosses 1)")
    if np.isfinite(m.gain_crossover):
        pm += f" at {m.gain_crossover:.4g} rad/s"
    if np.isnan(m.delay_margin_s):
        dm = "undefined (closed loop not stable)"
    else:
        dm = _fmt_margin(m.delay_margin_s, " s", "∞")
    ms_at = "" if not np.isfinite(m.ms_frequency) else f" at {m.ms_frequency:.4g} rad/s"
    if m.ms_frequency == np.inf:
        ms_at = " (as ω → ∞)"
    out.append("  loop broken at the plant input (L = −(u_p → u)):")
    out.append(f"    gain margin {gm}; phase margin {pm}")
    out.append(f"    delay margin {dm}; sensitivity peak Ms = {m.ms:.4g}{ms_at}")
    if m.open_loop_rhp_poles:
        out.append(f"    L has {m.open_loop_rhp_poles} right-half-plane pole(s)")
    return out


def format_linearization_text(
    lin: Linearization, name: str = "", extra: dict[str, Any] | None = None
) -> str:
    """Plain-text report of a :class:`Linearization` (``aiofl analyze CONFIG --closed-loop``).

    Eigenvalues are listed once per group with their multiplicity (``−50 ×3``,
    :func:`group_eigenvalues`)."""
    sampled = (extra or {}).get("sampled_loop")
    head = f"Closed-loop linearisation{f' of {name}' if name else ''}"
    if sampled is not None:  # the lines below are the continuous loop's: say so
        head += f" — the continuous loop (the design runs sampled at Ts = {sampled['ts']:g} s)"
    out = [head]
    out.append(
        f"  operating point: r = {lin.r_op:g}, τ_d = {lin.d_op:g}; states: "
        + ", ".join(lin.state_names)
    )
    out.append(f"  z* = [{', '.join(f'{v:.6g}' for v in lin.z_op)}]")
    groups = lin.eigenvalue_groups or tuple((complex(z), 1) for z in lin.eigenvalues)
    out.append(f"  eigenvalues ({len(lin.eigenvalues)}, exact Jacobian by the complex step):")
    for z, k in groups:
        if z.real < 0:
            tau = f"   decays, τ = {1 / abs(z.real):.4g} s"
        elif z.real > 0:
            tau = f"   GROWS, τ = {1 / z.real:.4g} s"
        else:
            tau = ""
        mult = f" ×{k}" if k > 1 else ""
        out.append(f"    {_fmt(z)}{mult}{tau}")
    out.append(f"  slowest mode: {_fmt(lin.slowest)}   fastest mode: {_fmt(lin.fastest)}")
    out.append(f"  verdict: {lin.verdict().upper()} (max Re = {lin.max_real:.6g})")
    out += format_margins_text(lin)
    for note in lin.notes:
        out.append(f"  note: {note}")
    for note in lin.margins.notes:
        out.append(f"  note: {note}")
    if extra and "verdicts_by_amplitude" in extra:
        sweep = ", ".join(f"ε={k}: {v}" for k, v in extra["verdicts_by_amplitude"].items())
        out.append(f"  verdict by error amplitude: {sweep}")
    if sampled is not None:
        out += format_sampled_text(sampled)
    return "\n".join(out)


def format_sampled_text(sampled: dict[str, Any]) -> list[str]:
    """Text lines of :func:`aiofl.analysis.sampled_loop.sampled_margins`."""
    ts = sampled["ts"]
    out = [f"Sampled loop at Ts = {ts:g} s (ZOH plant + the engine's discrete update, linearised)"]
    if "reason" in sampled:
        return [*out, f"  not analysed: {sampled['reason']}"]
    word = "STABLE" if sampled["stable"] else "UNSTABLE"
    out.append(f"  verdict: {word} (spectral radius {sampled['spectral_radius']:.6g})")

    def at(w: float | None) -> str:
        return f" at {w:.4g} rad/s" if w is not None else ""

    gm, pm, dm = (sampled[k] for k in ("gain_margin_db", "phase_margin_deg", "delay_margin_s"))
    gm_text = f"{gm:.4g} dB{at(sampled['phase_crossover'])}" if gm is not None else "∞"
    pm_text = f"{pm:.4g}°{at(sampled['gain_crossover'])}" if pm is not None else "∞"
    dm_text = "not defined" if dm is None else f"{dm:.4g} s"
    out.append(
        f"  loop broken at the plant input, z = e^(jωTs), ω ≤ π/Ts = {np.pi / ts:.4g} rad/s:"
    )
    out.append(f"    gain margin {gm_text}; phase margin {pm_text}; delay margin {dm_text}")
    return out
