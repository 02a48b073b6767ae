r"""Linearisation of the whole closed loop (plant + TD + ESO + SEF + law) and its stability.

The closed loop of :mod:`aiofl.engine.kernel` is an ODE
:math:`\dot z = F(z; r, \tau_d, n)`.  This module writes the same equations in Python
(:class:`ClosedLoop`, checked against the engine in the tests), finds the operating point
:math:`z^*` with the reference held at a constant :math:`r^*` and the disturbance at its final
value, and linearises by central finite differences,

.. math:: A = \frac{\partial F}{\partial z}(z^*),\qquad
          \dot{\delta z} = A\,\delta z + B\,(\delta r, \delta\tau_d, \delta n),\quad
          (\delta y, \delta u) = C\,\delta z + D\,(\delta r, \delta\tau_d, \delta n).

The verdict is *stable* if every eigenvalue of A has a negative real part, *unstable* if
one has a positive real part, *marginal* otherwise (within a relative tolerance).

The closed loop itself, and how its non-smooth elements are linearised, is
:mod:`aiofl.analysis.closed_loop`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from aiofl.analysis.closed_loop import DEFAULT_AMPLITUDE, ClosedLoop
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
    "linear_eso_statespace",
    "linearize_closed_loop",
]

SWEEP_AMPLITUDES = (1e-4, 1e-3, 1e-2, 1e-1)
"""Amplitudes for ``verdicts_by_amplitude`` when the verdict may depend on ε."""


# ------------------------------------------------------------------ linearisation
@dataclass(frozen=True)
class Linearization:
    """The closed loop linearised at its operating point.

    Attributes
    ----------
    a, b, c, d
        State-space matrices; inputs ``(r, d, n)`` (reference, disturbance, measurement
        noise), outputs ``(y, u)``.
    state_names
        Names of the states (see :class:`ClosedLoop`).
    z_op, r_op, d_op
        Operating point.
    eigenvalues
        Eigenvalues of ``a``, sorted by decreasing real part.
    amplitude
        Error amplitude ε of the secant gains.
    notes
        How each non-smooth element was handled, and other remarks.
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

    input_names = ("r", "d", "n")
    output_names = ("y", "u")

    @property
    def max_real(self) -> float:
        """Largest real part of the eigenvalues."""
        return float(self.eigenvalues.real.max())

    def verdict(self, rtol: float = 1e-6) -> str:
        """``"stable"``, ``"unstable"`` or ``"marginal"`` (|max Re| ≤ rtol·max|λ|)."""
        return _verdict(self.eigenvalues, rtol)

    @property
    def slowest(self) -> complex:
        """The eigenvalue with the largest real part (slowest / least damped mode)."""
        return complex(self.eigenvalues[0])

    @property
    def fastest(self) -> complex:
        """The eigenvalue with the most negative real part."""
        return complex(self.eigenvalues[-1])

    def statespace(self) -> Any:
        """The linearised loop as a ``control.StateSpace`` (python-control)."""
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

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (``verdict``, ``eigenvalues`` as [[re, im], ...], ...)."""
        return {
            "verdict": self.verdict(),
            "eigenvalues": [[float(z.real), float(z.imag)] for z in self.eigenvalues],
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
    amplitude
        Error amplitude ε for the secant gains of fal / g(e) / INLSEF (module docstring).
    r_op
        Reference value to hold (default: see :func:`reference_operating_value`).

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
    a = loop.jacobian(z)
    # input and output matrices by central differences
    rho = controller.rho
    h = 1e-6

    def evaluate(zz: NDArray[np.float64], dr: float = 0.0, dd: float = 0.0, dn: float = 0.0) -> Any:
        rd = np.zeros(rho + 1)
        rd[0] = loop.r_op + dr
        return loop.rhs(zz, rd=rd, d=loop.d_op + dd, noise=dn)

    b_cols, d_cols = [], []
    for kw in ({"dr": h}, {"dd": h}, {"dn": h}):
        neg = {k: -v for k, v in kw.items()}
        fp, yp, up = evaluate(z, **kw)
        fm, ym, um = evaluate(z, **neg)
        b_cols.append((fp - fm) / (2 * h))
        d_cols.append([(yp - ym) / (2 * h), (up - um) / (2 * h)])
    c_rows = np.zeros((2, loop.n_z))
    for j in range(loop.n_z):
        hj = 1e-6 * max(1.0, abs(z[j]))
        zp, zm = z.copy(), z.copy()
        zp[j] += hj
        zm[j] -= hj
        _, yp, up = evaluate(zp)
        _, ym, um = evaluate(zm)
        c_rows[:, j] = [(yp - ym) / (2 * hj), (up - um) / (2 * hj)]
    eig = np.linalg.eigvals(a)
    eig = eig[np.lexsort((eig.imag, -eig.real))]
    notes = list(loop.nonsmooth)
    if controller.law == "iofl":
        notes.append("IOFL law: the ESO is integrated but not used; its poles do not interact")
    if scenario.noise_variance > 0:
        notes.append("measurement noise set to 0 at the operating point (it is an input n)")
    return Linearization(
        a=a,
        b=np.column_stack(b_cols),
        c=c_rows,
        d=np.array(d_cols).T,
        state_names=loop.state_names,
        z_op=z,
        r_op=loop.r_op,
        d_op=loop.d_op,
        eigenvalues=eig,
        amplitude=float(amplitude),
        notes=tuple(notes),
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
    """Stability verdict of a run config's linearised closed loop.

    ``run_config`` is a :class:`~aiofl.config.RunConfig` or a config path / preset name;
    ``linearization`` reuses a :func:`linearize_closed_loop` result at ``amplitude``
    (the default operating point) instead of computing it again.

    Returns
    -------
    dict
        ``{"verdict": "stable"|"unstable"|"marginal", "eigenvalues": [[re, im], ...],
        "max_real", "slowest", "fastest", "states", "operating_point", "amplitude",
        "notes"}`` and, when the secant gains depend on ε, ``"verdicts_by_amplitude"``
        (ε -> verdict over :data:`SWEEP_AMPLITUDES`).
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


def format_linearization_text(
    lin: Linearization, name: str = "", extra: dict[str, Any] | None = None
) -> str:
    """Plain-text report of a :class:`Linearization` (``aiofl analyze CONFIG --closed-loop``)."""
    out = [f"Closed-loop linearisation{f' of {name}' if name else ''}"]
    out.append(
        f"  operating point: r = {lin.r_op:g}, τ_d = {lin.d_op:g}; states: "
        + ", ".join(lin.state_names)
    )
    out.append(f"  z* = [{', '.join(f'{v:.6g}' for v in lin.z_op)}]")
    out.append(f"  eigenvalues ({len(lin.eigenvalues)}):")
    for z in lin.eigenvalues:
        if z.real < 0:
            tau = f"   decays, τ = {1 / abs(z.real):.4g} s"
        elif z.real > 0:
            tau = f"   GROWS, τ = {1 / z.real:.4g} s"
        else:
            tau = ""
        out.append(f"    {_fmt(z)}{tau}")
    out.append(f"  slowest mode: {_fmt(lin.slowest)}   fastest mode: {_fmt(lin.fastest)}")
    out.append(f"  verdict: {lin.verdict().upper()} (max Re = {lin.max_real:.6g})")
    for note in lin.notes:
        out.append(f"  note: {note}")
    if extra and "verdicts_by_amplitude" in extra:
        sweep = ", ".join(f"ε={k}: {v}" for k, v in extra["verdicts_by_amplitude"].items())
        out.append(f"  verdict by error amplitude: {sweep}")
    return "\n".join(out)
