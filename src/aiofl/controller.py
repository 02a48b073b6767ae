"""A controller as data: component kinds plus named parameter values.

:class:`Controller` is the host-side description of one closed-loop controller (ESO,
tracking differentiator, state error feedback, linearizing law).  It packs into one
integer row and one float row of the engine's batch arrays (:mod:`aiofl.layout`); a batch
of controllers that differ only in parameter values is built with
:func:`controller_batch`, which is what the tuner does for a whole population.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from types import MappingProxyType

import numpy as np
from numpy.typing import NDArray

from aiofl import layout as L
from aiofl.components.observers import binomial_alphas

__all__ = ["STRUCTURES", "Controller", "ControllerBatch", "controller_batch"]

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
        "law.u_max": float("inf"),
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


@dataclass(frozen=True)
class Controller:
    """One controller: which components, their order, and every parameter value by name.

    Parameters
    ----------
    eso, td, sef, law
        Component kinds: ``eso`` in {"linear", "improved"}, ``td`` in {"exact", "han",
        "improved", "linear"}, ``sef`` in {"nonlinear", "improved", "linear"}, ``law`` in
        {"aiofl", "iofl"}.
    rho
        Controller order ρ (the plant's relative degree); the ESO has ρ+1 states.
    n_feedback
        How many estimated states the SEF feeds back (paper: 2).
    values
        Parameter values by :data:`aiofl.layout.FLOAT_COLUMNS` name; unspecified ones take
        neutral defaults.  ``eso.alpha1..`` may be replaced by Gao's binomial choice with
        :meth:`with_binomial_alphas`.
    structure
        Label used in reports (``"LESO"``, ``"INLESO"``, ``"LADRC"``, ``"IOFL"``, ...).
    """

    eso: str = "linear"
    td: str = "han"
    sef: str = "nonlinear"
    law: str = "aiofl"
    rho: int = 4
    n_feedback: int = 2
    values: Mapping[str, float] = field(default_factory=dict)
    structure: str = "custom"

    def __post_init__(self) -> None:
        for kind, table in (
            ("eso", L.ESO_KINDS),
            ("td", L.TD_KINDS),
            ("sef", L.SEF_KINDS),
            ("law", L.LAW_KINDS),
        ):
            if getattr(self, kind) not in table:
                raise ValueError(
                    f"controller.{kind} = {getattr(self, kind)!r}; allowed: {', '.join(table)}"
                )
        if not 1 <= self.rho <= L.RHO_MAX:
            raise ValueError(f"controller.rho = {self.rho}; allowed: 1..{L.RHO_MAX}")
        if not 1 <= self.n_feedback <= self.rho:
            raise ValueError(
                f"controller.n_feedback = {self.n_feedback}; allowed: 1..rho ({self.rho})"
            )
        if self.td in ("han", "improved") and self.n_feedback > 2:
            raise ValueError(
                f"controller.n_feedback = {self.n_feedback} needs {self.n_feedback} reference "
                f"derivatives but the {self.td!r} differentiator supplies 2; allowed: 1..2 "
                "(or td = 'linear' / 'exact')"
            )
        unknown = sorted(set(self.values) - set(L.FLOAT_COLUMNS))
        if unknown:
            raise ValueError(f"unknown controller parameter(s): {', '.join(unknown)}")
        vals = {k: float(v) for k, v in self.values.items()}
        object.__setattr__(self, "values", MappingProxyType(vals))

    @classmethod
    def from_structure(cls, structure: str, *, rho: int = 4, **kwargs: object) -> Controller:
        """A controller with the component kinds of a named structure (see STRUCTURES)."""
        if structure not in STRUCTURES:
            raise ValueError(f"structure {structure!r}; allowed: {', '.join(STRUCTURES)}")
        eso, td, sef, law = STRUCTURES[structure]
        return cls(eso=eso, td=td, sef=sef, law=law, rho=rho, structure=structure, **kwargs)  # type: ignore[arg-type]

    def value(self, name: str) -> float:
        """Parameter ``name``, or its default."""
        return self.values.get(name, _DEFAULTS[name])

    def with_values(self, **values: float) -> Controller:
        """A copy with some parameters replaced; dotted names via ``**{"eso.omega0": 50}``."""
        return replace(self, values={**self.values, **values})

    def with_binomial_alphas(self) -> Controller:
        r"""A copy with Gao's :math:`\alpha_i = \binom{\rho+1}{i}` (observer poles at -ω0)."""
        alphas = binomial_alphas(self.rho)
        return self.with_values(**{f"eso.alpha{i + 1}": a for i, a in enumerate(alphas)})

    def int_row(self) -> NDArray[np.int64]:
        """The engine's integer row (kinds, ρ, number of fed-back states)."""
        row = np.zeros(L.N_INT, dtype=np.int64)
        row[L.I_ESO] = L.ESO_KINDS[self.eso]
        row[L.I_TD] = L.TD_KINDS[self.td]
        row[L.I_SEF] = L.SEF_KINDS[self.sef]
        row[L.I_LAW] = L.LAW_KINDS[self.law]
        row[L.I_RHO] = self.rho
        row[L.I_NFB] = self.n_feedback
        return row

    def float_row(self) -> NDArray[np.float64]:
        """The engine's float row, every column of :data:`aiofl.layout.FLOAT_COLUMNS`."""
        row = np.array([_DEFAULTS[n] for n in L.FLOAT_COLUMNS], dtype=np.float64)
        for name, val in self.values.items():
            row[L.FLOAT_COLUMNS[name]] = val
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
            floats[:, L.FLOAT_COLUMNS[name]] = np.asarray(col, dtype=np.float64)
    return ControllerBatch(np.ascontiguousarray(ints), np.ascontiguousarray(floats))
