r"""A controller as data: component kinds plus named parameter values.

:class:`Controller` is the host-side description of one closed-loop controller (ESO,
tracking differentiator, state error feedback, linearizing law).  It packs into one
integer row and one float row of the engine's batch arrays (:mod:`aiofl.layout`); a batch
of controllers that differ only in parameter values is built with
:func:`controller_batch`, which is what the tuner does for a whole population.

Defaults are chosen so that a controller built with few arguments works:

* ``n_feedback`` (how many estimated states the SEF feeds back) defaults to ρ, full state
  feedback of the chain of integrators (14), which a linear SEF needs to place all ρ
  tracking poles; only with Han's TD (18) or the ITD (21), which supply r and ṙ alone (the
  paper's LESO and INLESO structures), it defaults to the paper's 2 (min(2, ρ)).
* the ESO's :math:`\alpha_i` default to Gao's binomial :math:`\binom{\rho+1}{i}`
  (observer poles at :math:`-\omega_0`, :func:`aiofl.components.observers.binomial_alphas`),
  as ``alpha = "binomial"`` does in a TOML config.
* the actuator range is :math:`[u_{min}, u_{max}] = [-\infty, \infty]`; a ``law.u_max``
  alone gives the symmetric range :math:`[-u_{max}, u_{max}]`.

With ``eso_gains = "kalman"`` the linear ESO's gains are the steady-state Kalman gains of
the process- and measurement-noise intensities ``eso.q`` and ``eso.r``
(:mod:`aiofl.components.kalman`): the continuous Kalman–Bucy gains are exactly
:math:`\beta_i = \alpha_i\omega_0^i` with the Butterworth :math:`\alpha_i` and
:math:`\omega_0 = (q/r)^{1/(2\rho+2)}`, which :meth:`Controller.value`,
:meth:`Controller.float_row` and :func:`controller_batch` write into the ``eso.omega0``
and ``eso.alpha*`` columns (so the engine, the analyses and the reports see the
equivalent bandwidth); a sampled controller gets the discrete Kalman gain instead
(:func:`aiofl.engine.discrete_rows.sampling_rows`).

:meth:`Controller.check_plant` refuses a controller that cannot drive a plant: ρ different
from the plant's known relative degree (unless ``allow_rho_mismatch``), an IOFL law on a
plant without a normal form (or where β(x0) = 0), and a ``law.b0`` whose sign differs
from the plant's high-frequency gain :math:`\beta = L_gL_f^{\rho-1}h` at the initial state
(unless ``allow_b0_sign_mismatch``).  The engine and the config loader call it.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from types import MappingProxyType
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from aiofl import layout as L
from aiofl.checks import check_integer, check_number
from aiofl.components.kalman import kalman_gain_parameters
from aiofl.components.observers import binomial_alphas
from aiofl.text import check_text

__all__ = [
    "STRUCTURES",
    "Controller",
    "ControllerBatch",
    "PlantLike",
    "controller_batch",
    "default_n_feedback",
    "resolve_kalman_rows",
    "value_range",
]

STRUCTURES = MappingProxyType(
    {
        # name: (eso, td, sef, law)
        "LESO": ("linear", "han", "nonlinear", "aiofl"),
        "INLESO": ("improved", "improved", "improved", "aiofl"),
        "LADRC": ("linear", "linear", "linear", "aiofl"),
        "IOFL": ("linear", "exact", "linear", "iofl"),
    }
)
"""The paper's two structures (LESO: LESO + NLSEF + Han TD; INLESO: INLESO + INLSEF +
ITD), a fully linear ADRC, and the classical model-based IOFL baseline."""

_DEFAULTS: dict[str, float] = {name: 0.0 for name in L.FLOAT_COLUMNS}
_DEFAULTS.update(
    {
        "law.b0": 1.0,
        "law.u_max": math.inf,
        "law.u_min": math.nan,  # "not given": the kernel uses -u_max (a symmetric range)
        "eso.omega0": 10.0,
        "eso.k_alpha": 1.0,
        "eso.k_beta": 0.0,
        "eso.g_alpha": 1.0,
        "eso.g_beta": 0.0,
        "td.R": 100.0,
        "td.a": 0.0,
        "td.b": 1.0,
        "td.c": 1.0,
        "td.rho": 10.0,
        "td.omega": 10.0,
        "sef.v_limit": 1.0,
        "sef.omega_c": 1.0,
    }
)
for _i in range(1, L.RHO_MAX + 1):
    _DEFAULTS[f"sef.k{_i}"] = 1.0
    _DEFAULTS[f"sef.alpha{_i}"] = 1.0
    _DEFAULTS[f"sef.delta{_i}"] = 1.0


#: allowed values of the parameters, by name or vector prefix (``sef.alpha`` covers
#: ``sef.alpha1..8``): the ranges of the config's ``[controller.*]`` tables
#: (:mod:`aiofl.config.schema`; ``tests/test_api_parity.py`` checks they agree)
_VALUE_RANGES: dict[str, dict[str, float]] = {
    "eso.omega0": {"gt": 0.0},
    "eso.alpha": {"ge": 0.0},
    "eso.k_alpha": {"ge": 0.0},
    "eso.k_beta": {"ge": 0.0},
    "eso.g_alpha": {"gt": 0.0, "le": 2.0},
    "eso.g_beta": {"ge": 0.0, "le": 2.0},
    "eso.q": {"gt": 0.0, "le": 1e300},
    "eso.r": {"gt": 0.0, "le": 1e300},
    "eso.u0": {},
    "eso.delay": {"ge": 0.0, "le": 1.0},  # and a whole number of samples, <= 8 (discrete)
    "td.R": {"gt": 0.0},
    "td.a": {"ge": 0.0, "lt": 1.0},
    "td.b": {"gt": 0.0},
    "td.c": {"gt": 0.0},
    "td.rho": {"gt": 0.0},
    "td.omega": {"gt": 0.0},
    "sef.k": {},
    "sef.kb": {},
    "sef.alpha": {"gt": 0.0, "le": 3.0},
    "sef.delta": {"gt": 0.0},
    "sef.mu": {"ge": 0.0},
    "sef.v_limit": {"gt": 0.0},
    "sef.omega_c": {"gt": 0.0},
    "law.b0": {},  # and non-zero (Controller.__post_init__)
}


def value_range(name: str) -> tuple[dict[str, float], bool]:
    """The bounds (``gt``/``ge``/``lt``/``le``) of parameter ``name`` and whether it must be
    finite (the actuator limits ``law.u_max`` / ``law.u_min`` may be ±inf)."""
    if name in ("law.u_max", "law.u_min"):
        return {}, False
    key = name if name in _VALUE_RANGES else name.rstrip("0123456789")
    return dict(_VALUE_RANGES[key]), True


def default_n_feedback(rho: int, td: str) -> int:
    r"""The default number of fed-back estimated states for order ``rho`` and TD kind ``td``.

    ρ (full state feedback of the chain (14); a linear SEF needs all ρ to place ρ poles),
    except behind Han's TD (18) or the ITD (21), which supply only :math:`r_1, r_2`: there
    the paper's 2 (text after eq. 22), i.e. :math:`\min(2, \rho)`.
    """
    return min(2, rho) if td in ("han", "improved") else rho


class PlantLike(Protocol):
    """What :meth:`Controller.check_plant` reads of a plant (:class:`aiofl.plants.base.Plant`)."""

    @property
    def name(self) -> str: ...

    @property
    def n_states(self) -> int: ...

    @property
    def relative_degree(self) -> int | None: ...

    @property
    def normal_form(self) -> Callable[..., Any] | None: ...

    def param_vector(self) -> NDArray[np.float64]: ...


@dataclass(frozen=True)
class Controller:
    r"""One controller: which components, their order, and every parameter value by name.

    Parameters
    ----------
    eso, td, sef, law
        Component kinds: ``eso`` in {"linear", "improved"}, ``td`` in {"exact", "han",
        "improved", "linear"}, ``sef`` in {"nonlinear", "improved", "linear"}, ``law`` in
        {"aiofl", "iofl"}.
    rho
        Controller order ρ (the plant's relative degree); the ESO has ρ+1 states.
    n_feedback
        How many estimated states the SEF feeds back, 1..ρ.  Default
        (:func:`default_n_feedback`): ρ, or the paper's 2 behind Han's TD / the ITD, which
        supply only two reference derivatives.
    values
        Parameter values by :data:`aiofl.layout.FLOAT_COLUMNS` name; unspecified ones take
        defaults (:meth:`value`): ``eso.alpha1..alpha{ρ+1}`` Gao's binomial
        :math:`\binom{\rho+1}{i}`, ``law.b0`` 1, no actuator limits, unit SEF vectors.
        ``law.b0`` must be finite and non-zero (negative for a plant whose high-frequency
        gain is negative); ``law.u_min < law.u_max`` (``u_min`` omitted: ``-u_max``).
    structure
        Label used in reports (``"LESO"``, ``"INLESO"``, ``"LADRC"``, ``"IOFL"``, ...).
    eso_init
        ``"zero"``: :math:`\hat\xi(0) = 0`; ``"output"``: :math:`\hat\xi_1(0) = y_m(0)`, the
        first measurement, the other states 0 (no initial output-estimate error);
        ``"bumpless"``: ``"output"`` and the differentiator / prefilter at rest at
        :math:`y_m(0)` (:math:`r_1(0) = y_m(0)`, its other states 0), so a plant at rest at
        :math:`y_0 = r` starts with :math:`e = 0, \hat\xi_{\rho+1} = 0`, i.e. u(0) = 0
        (the exported C's default start).  With ``values["eso.u0"]`` = :math:`u_0` (a
        start at an operating point, e.g. its holding input :math:`u_e`,
        :func:`aiofl.plants.operating_point.trim`) the extended state starts at
        :math:`\hat\xi_{\rho+1}(0) = -b_0 u_0`, the total disturbance of a plant held by
        :math:`u_0`, so :math:`u(0) = u_0` (industry's bumpless transfer: the new controller
        takes over the command that holds the plant).
    eso_model
        What the observer is given besides ρ and b0 (:data:`aiofl.layout.ESO_MODEL_KINDS`):
        ``"none"`` (model-free, eq. 5: :math:`\hat\xi_{\rho+1}` estimates the whole total
        disturbance) or ``"nominal"`` (model-assisted: the ρ-th observer equation and the
        law carry the plant's nominal :math:`\alpha_0(\hat x) + \beta_0(\hat x)u` at
        :math:`\hat x = \Phi^{-1}(\hat\xi)`, and :math:`\hat\xi_{\rho+1}` estimates
        only what the model misses; :func:`aiofl.components.law.model_assisted_law`).  Needs
        a plant with ``alpha_beta_of_xi`` (symbolic plants with ρ = n have it).
    allow_rho_mismatch
        Let :meth:`check_plant` accept a ρ different from the plant's known relative degree
        (e.g. to study a reduced-order design); refused otherwise.
    allow_b0_sign_mismatch
        Let :meth:`check_plant` accept a ``law.b0`` whose sign differs from the plant's
        :math:`\beta(x_0)`; refused otherwise.
    eso_gains
        ``"bandwidth"``: :math:`\beta_i = \alpha_i\omega_0^i` from ``eso.omega0`` and
        ``eso.alpha*``; ``"kalman"``: the steady-state Kalman gains of the process-noise
        intensity ``eso.q`` (on the extended state's derivative) and the measurement-noise
        intensity ``eso.r``, both required and positive (linear ESO only; ``eso.omega0``
        and ``eso.alpha*`` are then derived and may not be given,
        :mod:`aiofl.components.kalman`).
    """

    eso: str = "linear"
    td: str = "han"
    sef: str = "nonlinear"
    law: str = "aiofl"
    rho: int = 4
    n_feedback: int | None = None
    values: Mapping[str, float] = field(default_factory=dict)
    structure: str = "custom"
    eso_init: str = "zero"
    eso_model: str = "none"
    allow_rho_mismatch: bool = False
    allow_b0_sign_mismatch: bool = False
    eso_gains: str = "bandwidth"

    def __post_init__(self) -> None:
        check_text("controller.structure", self.structure)  # a label: reports, C comments
        for kind, table in (
            ("eso", L.ESO_KINDS),
            ("td", L.TD_KINDS),
            ("sef", L.SEF_KINDS),
            ("law", L.LAW_KINDS),
            ("eso_init", L.ESO_INIT_KINDS),
            ("eso_model", L.ESO_MODEL_KINDS),
            ("eso_gains", L.ESO_GAINS_KINDS),
        ):
            if not isinstance(getattr(self, kind), str) or getattr(self, kind) not in table:
                raise ValueError(
                    f"controller.{kind} = {getattr(self, kind)!r}; allowed: {', '.join(table)}"
                )
        if self.eso_model != "none" and self.law != "aiofl":
            raise ValueError(
                f"controller.eso_model = {self.eso_model!r} with law = {self.law!r}: the "
                "model-assisted observer belongs to the active law; allowed: law = 'aiofl'"
            )
        if isinstance(self.rho, bool) or not isinstance(self.rho, (int, np.integer)):
            raise ValueError(f"controller.rho = {self.rho!r}; allowed: an integer 1..{L.RHO_MAX}")
        if not 1 <= self.rho <= L.RHO_MAX:
            raise ValueError(f"controller.rho = {self.rho}; allowed: 1..{L.RHO_MAX}")
        object.__setattr__(self, "rho", int(self.rho))
        if self.n_feedback is None:
            object.__setattr__(self, "n_feedback", default_n_feedback(self.rho, self.td))
        nfb = check_integer("controller.n_feedback", self.n_feedback, ge=1, le=L.RHO_MAX)
        object.__setattr__(self, "n_feedback", nfb)
        for flag in ("allow_rho_mismatch", "allow_b0_sign_mismatch"):
            if not isinstance(getattr(self, flag), (bool, np.bool_)):
                raise ValueError(f"controller.{flag} = {getattr(self, flag)!r}; allowed: a bool")
        if not isinstance(self.values, Mapping):
            raise ValueError(
                f"controller.values = {self.values!r}; allowed: a mapping of parameter names "
                "(e.g. 'eso.omega0') to numbers"
            )
        if not 1 <= self.n_feedback <= self.rho:  # type: ignore[operator]
            raise ValueError(
                f"controller.n_feedback = {self.n_feedback}; allowed: 1..rho ({self.rho})"
            )
        if self.td in ("han", "improved") and self.n_feedback > 2:  # type: ignore[operator]
            raise ValueError(
                f"controller.n_feedback = {self.n_feedback} needs {self.n_feedback} reference "
                f"derivatives but the {self.td!r} differentiator supplies 2; allowed: 1..2 "
                "(or td = 'linear' / 'exact')"
            )
        unknown = sorted(set(self.values) - set(L.FLOAT_COLUMNS))
        if unknown:
            raise ValueError(f"unknown controller parameter(s): {', '.join(unknown)}")
        vals = {}
        for name, value in self.values.items():  # the ranges of the config's tables
            bounds, finite = value_range(name)
            vals[name] = check_number(f"controller.{name}", value, finite=finite, **bounds)
        object.__setattr__(self, "values", MappingProxyType(vals))
        b0 = self.value("law.b0")
        if not (math.isfinite(b0) and b0 != 0.0):
            raise ValueError(
                f"controller.law.b0 = {b0}; allowed: finite and non-zero (negative for a "
                "plant whose high-frequency gain is negative)"
            )
        self.u_range()  # validates law.u_min / law.u_max
        u0 = self.value("eso.u0")
        held = self.eso_init != "zero" and self.eso_model == "none" and self.law == "aiofl"
        if u0 != 0.0 and not held:
            raise ValueError(
                f"controller.eso.u0 = {u0} (a start at the held command u0) needs the active "
                "law with a model-free observer started at the output; allowed: eso.init = "
                "'output' or 'bumpless', eso.model = 'none', law = 'aiofl' (or eso.u0 = 0)"
            )
        if self.eso_gains == "kalman":
            self._check_kalman()

    def _check_kalman(self) -> None:
        """Refuse what contradicts ``eso_gains = "kalman"`` (see the class notes)."""
        if self.eso != "linear":
            raise ValueError(
                f"controller.eso.gains = 'kalman' needs the linear ESO (got eso = "
                f"{self.eso!r}): the improved ESO (INLESO) injects the nonlinear g(e) of "
                "eq. (19), for which the Kalman gains of the linear chain are not optimal; "
                "allowed: eso.gains = 'bandwidth', or a linear ESO (eso_kind = 'linear')"
            )
        fixed = sorted(n for n in self.values if n == "eso.omega0" or n.startswith("eso.alpha"))
        if fixed:
            raise ValueError(
                f"controller.eso.gains = 'kalman' derives eso.omega0 and eso.alpha from "
                f"eso.q and eso.r, but {', '.join(fixed)} given too; remove them, or use "
                "eso.gains = 'bandwidth'"
            )
        for name in ("eso.q", "eso.r"):
            if name not in self.values:
                raise ValueError(
                    f"controller.eso.gains = 'kalman' needs controller.{name} (process-noise "
                    "intensity q, measurement-noise intensity r); allowed: finite and > 0"
                )
        kalman_gain_parameters(self.rho, self.values["eso.q"], self.values["eso.r"])

    @classmethod
    def from_structure(cls, structure: str, *, rho: int = 4, **kwargs: Any) -> Controller:
        """A controller with the component kinds of a named structure (see STRUCTURES).

        The other fields (``n_feedback``, ``values``, ...) are passed on; their defaults are
        the class's (binomial ESO α, ``n_feedback`` from :func:`default_n_feedback`).

        Parameters
        ----------
        structure
            A key of :data:`STRUCTURES` (its ``eso``, ``td``, ``sef``, ``law``); else ValueError.
        rho
            The chain order ρ of the observer and feedback (default 4, the paper's plant).
        **kwargs
            Any other :class:`Controller` field (``n_feedback``, ``values``, ...).

        Returns
        -------
        Controller
        """
        if structure not in STRUCTURES:
            raise ValueError(f"structure {structure!r}; allowed: {', '.join(STRUCTURES)}")
        eso, td, sef, law = STRUCTURES[structure]
        return cls(eso=eso, td=td, sef=sef, law=law, rho=rho, structure=structure, **kwargs)

    def value(self, name: str) -> float:
        r"""Parameter ``name``, or its default.

        Defaults: ``eso.alpha{i}`` (i ≤ ρ+1) Gao's :math:`\binom{\rho+1}{i}`, or with
        Kalman gains the Butterworth α and ``eso.omega0`` :math:`(q/r)^{1/(2\rho+2)}`;
        ``law.u_min`` :math:`-u_{max}`; the rest from a fixed table (``law.b0`` 1,
        ``law.u_max`` ∞, SEF ``k``/``alpha``/``delta`` 1, ...).
        """
        if name in self.values:
            return self.values[name]
        if self.eso_gains == "kalman" and (name == "eso.omega0" or name.startswith("eso.alpha")):
            alphas, w0 = kalman_gain_parameters(
                self.rho, self.values["eso.q"], self.values["eso.r"]
            )
            if name == "eso.omega0":
                return w0
            i = int(name[len("eso.alpha") :])
            if i <= self.rho + 1:
                return float(alphas[i - 1])
        if name.startswith("eso.alpha"):
            i = int(name[len("eso.alpha") :])
            if i <= self.rho + 1:
                return float(binomial_alphas(self.rho)[i - 1])
        if name == "law.u_min":
            return -self.value("law.u_max")
        return _DEFAULTS[name]

    def u_range(self) -> tuple[float, float]:
        """The actuator range :math:`(u_{min}, u_{max})` the law's output is clipped to."""
        u_max = self.value("law.u_max")
        u_min = self.value("law.u_min")
        if math.isnan(u_max) or math.isnan(u_min):
            raise ValueError(
                f"controller.law.u_min = {u_min}, u_max = {u_max}; allowed: numbers (±inf "
                "for no limit)"
            )
        if not u_min < u_max:
            given = "law.u_min" in self.values
            raise ValueError(
                f"controller.law.u_min = {u_min} must be < u_max = {u_max}"
                if given
                else f"controller.law.u_max = {u_max}; allowed: > 0 (the range is "
                "[-u_max, u_max] unless u_min is given)"
            )
        return u_min, u_max

    def with_values(self, **values: float) -> Controller:
        """A copy with some parameters replaced; dotted names via ``**{"eso.omega0": 50}``."""
        return replace(self, values={**self.values, **values})

    def with_binomial_alphas(self) -> Controller:
        r"""A copy with Gao's :math:`\alpha_i = \binom{\rho+1}{i}` (observer poles at -ω0)
        written explicitly (they are also the default of unset α)."""
        alphas = binomial_alphas(self.rho)
        return self.with_values(**{f"eso.alpha{i + 1}": a for i, a in enumerate(alphas)})

    # ------------------------------------------------------------------ plant checks
    def plant_beta(self, plant: PlantLike, x0: Sequence[float] | None = None) -> float | None:
        r"""The plant's high-frequency gain :math:`\beta(x_0) = L_gL_f^{\rho-1}h(x_0)`.

        From its normal form at the nominal parameters and the initial state ``x0``
        (default: 0, the engine's default initial state); None if the plant has no normal
        form or no known relative degree.
        """
        rd = plant.relative_degree
        nf = plant.normal_form
        if nf is None or rd is None:
            return None
        x = np.zeros(plant.n_states) if not x0 else np.asarray(x0, dtype=np.float64)
        if x.shape != (plant.n_states,):
            raise ValueError(f"x0 has {x.size} entries; plant {plant.name!r} has {plant.n_states}")
        try:
            out = np.asarray(nf(x, plant.param_vector()), dtype=np.float64).ravel()
        except Exception as exc:  # a user function that fails at x0
            raise ValueError(
                f"plant {plant.name!r}: normal_form(x, p) failed at x0 = {x.tolist()}: {exc}"
            ) from exc
        if out.shape != (rd + 2,):
            raise ValueError(
                f"plant {plant.name!r}: normal_form(x, p) must return ρ+2 = {rd + 2} floats "
                f"(ξ_1..ξ_ρ, α, β); got {out.shape[0]}"
            )
        return float(out[rd + 1])

    def check_plant(self, plant: PlantLike, x0: Sequence[float] | None = None) -> None:
        r"""Raise ``ValueError`` if this controller cannot drive ``plant`` from ``x0``.

        * ρ must equal the plant's relative degree where it is known (an AIOFL loop of
          another order runs but tracks the wrong derivative chain), unless
          ``allow_rho_mismatch``;
        * the IOFL law needs the plant's normal form, ρ equal to the relative degree (no
          override: the law is built from that normal form) and
          :math:`\beta(x_0) \ne 0` (it divides by β);
        * ``law.b0`` must have the sign of :math:`\beta(x_0)` (the ESO's input gain, eq. 5:
          with the wrong sign the loop's feedback is positive), unless
          ``allow_b0_sign_mismatch``.
        """
        rd = plant.relative_degree
        name = plant.name
        if self.eso_model == "nominal":
            if getattr(plant, "alpha_beta_of_xi", None) is None or rd is None:
                raise ValueError(
                    f"controller.eso.model = 'nominal' needs the plant's normal form in its own "
                    f"coordinates, (α, β)(Φ⁻¹(ξ̂)); plant {name!r} has none (a plain Python "
                    "plant without alpha_beta_of_xi, or one with internal dynamics, ρ < n, "
                    "whose state the observer's ξ̂ does not determine): use a symbolic plant "
                    "file or give Plant(alpha_beta_of_xi=...), or eso.model = 'none'"
                )
            if rd != self.rho:
                raise ValueError(
                    f"controller.rho = {self.rho} but plant {name!r} has relative degree {rd}; "
                    "the model-assisted observer carries the plant's normal form and needs "
                    f"them equal (set controller.rho = {rd})"
                )
        if self.law == "iofl":
            if plant.normal_form is None or rd is None:
                raise ValueError(
                    f"controller.law = 'iofl' needs the plant's normal form (ξ, α(x), β(x)); "
                    f"plant {name!r} has none: give the Plant normal_form and relative_degree, "
                    "use a symbolic plant file, or law = 'aiofl' (which needs only ρ and b0)"
                )
            if rd != self.rho:
                raise ValueError(
                    f"controller.rho = {self.rho} but plant {name!r} has relative degree {rd}; "
                    "the IOFL law is built from the plant's normal form and needs them equal "
                    f"(set controller.rho = {rd})"
                )
        elif rd is not None and rd != self.rho and not self.allow_rho_mismatch:
            raise ValueError(
                f"controller.rho = {self.rho} but plant {name!r} has relative degree {rd}; "
                f"set controller.rho = {rd}, or controller.allow_rho_mismatch = true "
                "(Python: Controller(..., allow_rho_mismatch=True)) to run a controller of "
                "another order"
            )
        if x0 and len(x0) != plant.n_states:
            raise ValueError(
                f"scenario.x0 has {len(x0)} entries; plant {name!r} has {plant.n_states} states"
            )
        beta = self.plant_beta(plant, x0)
        where = f"x0 = {list(x0) if x0 else [0.0] * plant.n_states}"
        if self.law == "iofl" and (beta is None or not math.isfinite(beta) or beta == 0.0):
            raise ValueError(
                f"plant {name!r}: β = L_g L_f^(ρ-1) h = {beta} at {where}: the relative degree "
                "is not defined there and the IOFL law u = (v - α)/β divides by it; start "
                "elsewhere (scenario.x0) or use law = 'aiofl'"
            )
        b0 = self.value("law.b0")
        if (
            beta is not None
            and rd == self.rho
            and math.isfinite(beta)
            and beta != 0.0
            and (b0 > 0) != (beta > 0)
            and not self.allow_b0_sign_mismatch
        ):
            raise ValueError(
                f"controller.law.b0 = {b0:g} has the opposite sign of plant {name!r}'s "
                f"high-frequency gain β = L_g L_f^(ρ-1) h = {beta:.6g} at {where} (nominal "
                "parameters): the loop would feed back with the wrong sign; give b0 the sign "
                "of β, or set controller.allow_b0_sign_mismatch = true (Python: "
                "Controller(..., allow_b0_sign_mismatch=True))"
            )

    # ------------------------------------------------------------------ packing
    def int_row(self) -> NDArray[np.int64]:
        """The engine's integer row (kinds, ρ, number of fed-back states, ESO start)."""
        row = np.zeros(L.N_INT, dtype=np.int64)
        row[L.I_ESO] = L.ESO_KINDS[self.eso]
        row[L.I_TD] = L.TD_KINDS[self.td]
        row[L.I_SEF] = L.SEF_KINDS[self.sef]
        row[L.I_LAW] = L.LAW_KINDS[self.law]
        row[L.I_RHO] = self.rho
        row[L.I_NFB] = self.n_feedback
        row[L.I_ESO_INIT] = L.ESO_INIT_KINDS[self.eso_init]
        row[L.I_ESO_MODEL] = L.ESO_MODEL_KINDS[self.eso_model]
        row[L.I_ESO_GAINS] = L.ESO_GAINS_KINDS[self.eso_gains]
        return row

    def float_row(self) -> NDArray[np.float64]:
        r"""The engine's float row, every column of :data:`aiofl.layout.FLOAT_COLUMNS`.

        Unset α are the binomial defaults; an unset ``law.u_min`` is NaN, which the kernel
        reads as :math:`-u_{max}` (so a batch that varies ``law.u_max`` stays symmetric).
        With Kalman gains ``eso.omega0`` and ``eso.alpha*`` are the equivalent bandwidth
        form of ``eso.q``, ``eso.r`` (:func:`resolve_kalman_rows`).
        """
        row = np.array([_DEFAULTS[n] for n in L.FLOAT_COLUMNS], dtype=np.float64)
        alphas = binomial_alphas(self.rho)
        row[L.F_ESO_ALPHA : L.F_ESO_ALPHA + self.rho + 1] = alphas
        for name, val in self.values.items():
            row[L.FLOAT_COLUMNS[name]] = val
        resolve_kalman_rows(self.int_row()[None, :], row[None, :])
        return row


@dataclass(frozen=True)
class ControllerBatch:
    """Packed rows of a batch of controllers: ``ints`` (B, N_INT), ``floats`` (B, N_FLOAT)."""

    ints: NDArray[np.int64]
    floats: NDArray[np.float64]

    def __len__(self) -> int:
        return int(self.ints.shape[0])


def controller_batch(
    controllers: Controller | Sequence[Controller],
    values: Mapping[str, NDArray[np.float64]] | None = None,
) -> ControllerBatch:
    """Pack controllers into a batch.

    With one controller and ``values`` (name -> array of length B), the batch is B copies
    of it with those columns replaced, one member per entry: a GA population in one call.
    Members with Kalman gains get their ``eso.omega0`` and ``eso.alpha*`` from their own
    ``eso.q``, ``eso.r`` (:func:`resolve_kalman_rows`), so a tuned q is always the one used.
    """
    if isinstance(controllers, Controller):
        controllers = [controllers]
    ints = np.stack([c.int_row() for c in controllers])
    floats = np.stack([c.float_row() for c in controllers])
    if values:
        sizes = {np.asarray(v).shape[0] for v in values.values()}
        if len(sizes) != 1:
            raise ValueError("all value arrays must have the same length")
        (size,) = sizes
        if ints.shape[0] == 1:
            ints = np.repeat(ints, size, axis=0)
            floats = np.repeat(floats, size, axis=0)
        elif ints.shape[0] != size:
            raise ValueError(f"{ints.shape[0]} controllers but value arrays of length {size}")
        for name, col in values.items():
            if name not in L.FLOAT_COLUMNS:
                raise ValueError(f"unknown controller parameter {name!r}")
            column = np.asarray(col, dtype=np.float64)
            _check_column(name, column)
            floats[:, L.FLOAT_COLUMNS[name]] = column
        kalman = ints[:, L.I_ESO_GAINS] == L.ESO_GAINS_KALMAN
        derived = sorted(n for n in values if n == "eso.omega0" or n.startswith("eso.alpha"))
        if derived and kalman.any():
            raise ValueError(
                f"{', '.join(derived)}: derived from eso.q and eso.r for a controller with "
                "eso.gains = 'kalman'; vary eso.q / eso.r instead"
            )
        resolve_kalman_rows(ints, floats)
    return ControllerBatch(np.ascontiguousarray(ints), np.ascontiguousarray(floats))


def _check_column(name: str, column: NDArray[np.float64]) -> None:
    """Refuse a batch column with a value outside the parameter's range (:func:`value_range`;
    ``law.b0`` also non-zero), naming the parameter and the first bad member."""
    bounds, finite = value_range(name)
    ok = ~np.isnan(column) & (np.isfinite(column) | (not finite))
    ops = {"gt": np.greater, "ge": np.greater_equal, "lt": np.less, "le": np.less_equal}
    for key, edge in bounds.items():
        ok &= ops[key](column, edge)
    if name == "law.b0":
        ok &= column != 0.0
    bad = np.flatnonzero(~ok)
    if bad.size:
        i = int(bad[0])
        check_number(f"controller.{name} (member {i})", float(column[i]), finite=finite, **bounds)
        raise ValueError(f"controller.{name} (member {i}) = 0.0; allowed: finite and non-zero")


def resolve_kalman_rows(ints: NDArray[np.int64], floats: NDArray[np.float64]) -> None:
    r"""Write, in place, the Kalman members' ESO gains in the bandwidth form the engine reads.

    For every row with ``eso.gains = "kalman"`` (:data:`aiofl.layout.I_ESO_GAINS`):
    ``eso.omega0`` :math:`= (q/r)^{1/(2\rho+2)}` and ``eso.alpha1..alpha{ρ+1}`` the
    Butterworth α of the steady-state Kalman–Bucy gains, from the row's ``eso.q``,
    ``eso.r`` (:func:`aiofl.components.kalman.kalman_gain_parameters`; the Riccati
    equation is solved once per order ρ and scaled).  ``ValueError`` if a row's q or r is
    not finite and positive or its gains overflow.
    """
    for i in np.flatnonzero(ints[:, L.I_ESO_GAINS] == L.ESO_GAINS_KALMAN):
        rho = int(ints[i, L.I_RHO])
        alphas, w0 = kalman_gain_parameters(
            rho, float(floats[i, L.F_ESO_Q]), float(floats[i, L.F_ESO_R])
        )
        floats[i, L.F_OMEGA0] = w0
        floats[i, L.F_ESO_ALPHA : L.F_ESO_ALPHA + rho + 1] = alphas
