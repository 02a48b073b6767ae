r"""The plant interface: any SISO plant :math:`\dot x = f(x) + g(x)u + b_d(x)\tau_d,\ y = h(x)`.

A user writes the plant as plain Python functions of the state ``x`` (a float array of
length n) and a parameter vector ``p`` (a float array, named by :attr:`Plant.params`):

.. code-block:: python

    def f(x, p):            # drift, n floats
        return (x[1], -p[0] * np.sin(x[0]))
    def g(x, p):            # input vector field, n floats
        return (0.0, p[1])
    def h(x, p):            # output, one float
        return x[0]

Returning a tuple of floats is fastest (no allocation in the compiled loop); arrays also
work.  The engine compiles these with numba into its closed-loop kernel, so user plants run
as fast as the built-in ones.  :meth:`Plant.check` calls each function once in Python and
reports a function of the wrong shape by name before anything is compiled.

An optional ``normal_form(x, p) -> (ξ_1, ..., ξ_ρ, α, β)`` (see :mod:`aiofl.plants.normal_form`)
enables the classical IOFL baseline law.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from functools import cached_property
from types import MappingProxyType
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["Plant", "PlantError"]

PlantFunction = Callable[[NDArray[np.float64], NDArray[np.float64]], Any]


class PlantError(ValueError):
    """A plant definition that the engine cannot use (wrong shape, wrong types, bad name)."""


def _zero_bd(x: NDArray[np.float64], p: NDArray[np.float64]) -> Any:  # pragma: no cover - jitted
    return x * 0.0


@dataclass(frozen=True, eq=False)
class Plant:
    r"""A SISO plant :math:`\dot x = f(x,p) + g(x,p)u + b_d(x,p)\tau_d`, :math:`y = h(x,p)`.

    Parameters
    ----------
    name
        Identifier used in configs (e.g. ``"slfjm"``).
    n_states
        Dimension n of the state.
    f, g, h
        Drift, input vector field and output map, plain Python functions ``(x, p)``.
    params
        Nominal parameter values, in the order of the vector ``p`` the functions receive.
    bd
        Disturbance input vector field ``(x, p) -> n floats``; zero if omitted.
    relative_degree
        ρ, if known (used as the default controller order).
    normal_form
        Optional ``(x, p) -> (ξ_1..ξ_ρ, α(x), β(x))`` for the classical IOFL law.
    state_names, description
        Documentation.
    """

    name: str
    n_states: int
    f: PlantFunction
    g: PlantFunction
    h: PlantFunction
    params: Mapping[str, float]
    bd: PlantFunction | None = None
    relative_degree: int | None = None
    normal_form: PlantFunction | None = None
    state_names: tuple[str, ...] = ()
    description: str = ""
    _checked: dict[str, bool] = field(default_factory=dict, repr=False)

    def __post_init__(self) -> None:
        if not isinstance(self.n_states, int) or self.n_states < 1:
            raise PlantError(f"plant {self.name!r}: n_states must be an integer >= 1")
        for fname in ("f", "g", "h"):
            if not callable(getattr(self, fname)):
                raise PlantError(f"plant {self.name!r}: {fname} must be a function (x, p)")
        object.__setattr__(self, "params", MappingProxyType(dict(self.params)))
        if not self.state_names:
            names = tuple(f"x{i}" for i in range(1, self.n_states + 1))
            object.__setattr__(self, "state_names", names)

    # ------------------------------------------------------------------ parameters
    @property
    def param_names(self) -> tuple[str, ...]:
        """Names of the entries of the parameter vector ``p``, in order."""
        return tuple(self.params)

    def param_vector(
        self, overrides: Mapping[str, float] | None = None, scale: Mapping[str, float] | None = None
    ) -> NDArray[np.float64]:
        """The parameter vector ``p`` with some values replaced (``overrides``) or scaled.

        ``scale={"J_l": 1.4}`` gives the paper's scenario-2 plant.
        """
        values = dict(self.params)
        for source, op in ((overrides, "set"), (scale, "scale")):
            for key, val in (source or {}).items():
                if key not in values:
                    raise PlantError(
                        f"plant {self.name!r} has no parameter {key!r}; "
                        f"allowed: {', '.join(self.param_names)}"
                    )
                values[key] = float(val) if op == "set" else values[key] * float(val)
        return np.array(list(values.values()), dtype=np.float64)

    # ------------------------------------------------------------------ evaluation
    def _vector(self, fn: PlantFunction, fname: str, x: ArrayLike, p: ArrayLike) -> np.ndarray:
        out = fn(np.asarray(x, dtype=np.float64), np.asarray(p, dtype=np.float64))
        if isinstance(out, tuple) and any(isinstance(v, (int, np.integer)) for v in out):
            raise PlantError(
                f"plant {self.name!r}: {fname}(x, p) returns an integer entry; return floats "
                "(write 0.0, not 0) so the compiled engine sees one element type"
            )
        arr = np.asarray(out, dtype=np.float64)
        if arr.shape != (self.n_states,):
            raise PlantError(
                f"plant {self.name!r}: {fname}(x, p) must return {self.n_states} floats "
                f"(one per state), got shape {arr.shape}"
            )
        return arr

    def rhs(self, x: ArrayLike, u: float, d: float = 0.0, p: ArrayLike | None = None) -> np.ndarray:
        r""":math:`\dot x = f(x,p) + g(x,p)u + b_d(x,p)\tau_d`, evaluated in Python."""
        pv = self.param_vector() if p is None else np.asarray(p, dtype=np.float64)
        dx = self._vector(self.f, "f", x, pv) + self._vector(self.g, "g", x, pv) * u
        if self.bd is not None and d != 0.0:
            dx = dx + self._vector(self.bd, "bd", x, pv) * d
        return dx

    def output(self, x: ArrayLike, p: ArrayLike | None = None) -> float:
        """:math:`y = h(x, p)`, evaluated in Python."""
        pv = self.param_vector() if p is None else np.asarray(p, dtype=np.float64)
        out = np.asarray(self.h(np.asarray(x, dtype=np.float64), pv), dtype=np.float64)
        if out.shape not in ((), (1,)):
            raise PlantError(
                f"plant {self.name!r}: h(x, p) must return one float, got shape {out.shape}"
            )
        return float(out.reshape(()))

    def check(self, x: ArrayLike | None = None) -> None:
        """Call every function once in Python and raise :class:`PlantError` on a wrong shape."""
        x = np.full(self.n_states, 0.1) if x is None else np.asarray(x, dtype=np.float64)
        if x.shape != (self.n_states,):
            raise PlantError(f"plant {self.name!r}: x0 must have {self.n_states} entries")
        p = self.param_vector()
        for fname in ("f", "g", "h", "bd", "normal_form"):
            fn = getattr(self, fname)
            if fn is None:
                continue
            try:
                if fname == "h":
                    self.output(x, p)
                elif fname == "normal_form":
                    nf = np.asarray(fn(x, p), dtype=np.float64)
                    rho = self.relative_degree
                    if rho is None or nf.shape != (rho + 2,):
                        raise PlantError(
                            f"plant {self.name!r}: normal_form(x, p) must return ρ+2 floats "
                            f"(ξ_1..ξ_ρ, α, β) with relative_degree set; got shape {nf.shape}"
                        )
                else:
                    self._vector(fn, fname, x, p)
            except PlantError:
                raise
            except Exception as exc:  # a user function that raises on a valid state
                raise PlantError(
                    f"plant {self.name!r}: {fname}(x, p) failed on x={x.tolist()}: {exc}"
                ) from exc

    # ------------------------------------------------------------------ compilation
    @cached_property
    def compiled(self) -> tuple[Any, Any, Any, Any, Any]:
        """The numba-compiled ``(f, g, h, bd, normal_form)`` the engine's kernel calls."""
        from numba import njit

        self.check()
        nf = self.normal_form
        if nf is None:
            n = self.n_states

            def nf(x: NDArray[np.float64], p: NDArray[np.float64]) -> Any:  # placeholder
                return np.zeros(n + 2)

        jit = njit
        return (
            jit(self.f),
            jit(self.g),
            jit(self.h),
            jit(self.bd or _zero_bd),
            jit(nf),
        )
