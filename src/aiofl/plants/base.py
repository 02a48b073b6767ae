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
reports a function of the wrong shape, or one that returns complex numbers, by name before
anything is compiled (given the initial state it also requires finite values there);
:meth:`Plant.typecheck` compiles each function as the kernel calls it and reports one numba
cannot compile (a Python ``dict``, an unsupported library call) or whose compiled result is
not real floats, by name.

**Failures at run time.**  The plant functions are compiled with numba's ``numpy`` error
model, like the kernel: a division by zero, an overflow or a math domain error (``sqrt`` or
``log`` of a negative number) gives ``inf`` or ``NaN`` as in numpy, the member's state
becomes non-finite and the engine reports it *diverged* at that time (no NaN in the
results).  A plant function that raises (``raise ValueError(...)``) stops the run with a
:class:`PlantError` naming the plant, the function and the state where it failed
(:func:`aiofl.engine.build.instances.run_groups`).

An optional ``normal_form(x, p) -> (ξ_1, ..., ξ_ρ, α, β)`` (see :mod:`aiofl.plants.normal_form`)
enables the classical IOFL baseline law.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from functools import cached_property
from types import MappingProxyType
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from aiofl.checks import check_number
from aiofl.text import (
    MAX_DESCRIPTION_CHARS,
    MAX_UNIT_CHARS,
    check_distinct,
    check_name,
    check_text,
    normal_keys,
    normal_name,
)

__all__ = ["Plant", "PlantError", "derivative_unit", "unit_from_label", "unit_label"]

PlantFunction = Callable[[NDArray[np.float64], NDArray[np.float64]], Any]


class PlantError(ValueError):
    """A plant definition that the engine cannot use (wrong shape, wrong types, bad name)."""


def unit_label(name: str, unit: str) -> str:
    """``"name [unit]"``, or just ``name`` when the unit is not declared (``""`` or ``"-"``)."""
    return f"{name} [{unit}]" if unit and unit != "-" else name


def derivative_unit(unit: str, k: int) -> str:
    r"""The unit of the k-th time derivative of a signal in ``unit``: ``rad`` -> ``rad/s^2``.

    The ESO's estimates :math:`\hat\xi_{k+1}` of :math:`y^{(k)}` (eq. 5) and the
    differentiator's :math:`r_{k+1}` carry these units; an undeclared unit stays undeclared.
    """
    if not unit or unit == "-" or k == 0:
        return unit
    return f"{unit}/s" if k == 1 else f"{unit}/s^{k}"


def unit_from_label(label: str) -> str:
    """The unit in a state label's trailing brackets: ``"hub angle θ [rad]"`` -> ``"rad"``."""
    text = label.strip()
    if text.endswith("]") and "[" in text:
        return text[text.rindex("[") + 1 : -1].strip()
    return ""


def _no_alpha_beta(xi: NDArray[np.float64], p: NDArray[np.float64]) -> Any:  # pragma: no cover
    return (0.0, 1.0)  # placeholder: a controller that needs the model is refused first


def _zero_bd(x: NDArray[np.float64], p: NDArray[np.float64]) -> Any:  # pragma: no cover - jitted
    return x * 0.0


def _range_pair(field_name: str, pair: Any) -> tuple[float, float]:
    """``(low, high)`` as floats, low < high, neither NaN (±inf or None leaves a side open)."""
    allowed = "allowed: a pair (low, high) of numbers with low < high (±inf leaves a side open)"
    if isinstance(pair, (str, bytes)) or not hasattr(pair, "__len__") or len(pair) != 2:
        raise PlantError(f"{field_name} = {pair!r}; {allowed}")
    try:
        lo = -math.inf if pair[0] is None else float(pair[0])
        hi = math.inf if pair[1] is None else float(pair[1])
    except (TypeError, ValueError):
        raise PlantError(f"{field_name} = {pair!r}; {allowed}") from None
    if isinstance(pair[0], bool) or isinstance(pair[1], bool) or not lo < hi:
        raise PlantError(f"{field_name} = {pair!r}; {allowed}")
    return lo, hi


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
    alpha_beta_of_xi
        Optional ``(ξ, p) -> (α, β)``: the normal form :math:`y^{(\rho)} = \alpha +
        \beta u` in its own coordinates, :math:`\alpha(\Phi^{-1}(\xi))`,
        :math:`\beta(\Phi^{-1}(\xi))` (ρ = n), for the model-assisted observer
        (``eso.model = "nominal"``).  Generated for symbolic plants
        (:attr:`aiofl.plants.normal_form.Analysis.alpha_beta_of_xi`).
    state_of_xi
        Optional ``(ξ, p) -> x``, :math:`\Phi^{-1}`: the state with normal-form coordinates ξ.
    state_names, description
        Documentation.
    output_unit, input_unit, disturbance_unit
        Units of y, u and τ_d as plain text (``"rad"``, ``"V"``, ``"N·m"``); ``""`` when not
        declared.  Figures, CSV headers and report tables label signals with them.
    state_units
        One unit per state (``"rad/s"``); empty strings when not declared.
    state_bounds
        Physical ranges of some states, ``{name: (low, high)}`` (±inf leaves a side open):
        a run whose state leaves its range is *lost* (a levitated ball on the magnet or on
        the floor, a joint past its stop; :mod:`aiofl.engine.kernel.loop`).
    output_range
        The output's physical range ``(low, high)``, or None; leaving it makes a run lost.

    Examples
    --------
    A first-order lag :math:`\dot x = (u - x)/\tau`, :math:`y = x`; the functions are
    compiled (numba) on the first simulation, evaluated in Python here:

    >>> import numpy as np
    >>> def f(x, p):
    ...     return np.array([-x[0] / p[0]])
    >>> def g(x, p):
    ...     return np.array([1.0 / p[0]])
    >>> def h(x, p):
    ...     return x[0]
    >>> lag = Plant("lag", 1, f, g, h, {"tau": 0.5}, relative_degree=1)
    >>> lag.rhs([1.0], u=2.0)
    array([2.])
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
    alpha_beta_of_xi: PlantFunction | None = None
    state_of_xi: PlantFunction | None = None
    state_names: tuple[str, ...] = ()
    description: str = ""
    output_unit: str = ""
    input_unit: str = ""
    state_units: tuple[str, ...] = ()
    disturbance_unit: str = ""
    state_bounds: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    output_range: tuple[float, float] | None = None
    _checked: dict[str, bool] = field(default_factory=dict, repr=False)

    def __post_init__(self) -> None:
        try:  # the text rule of aiofl.text, before the name is used in any message
            check_text("plant.name", self.name)
            check_text("plant.description", self.description, max_chars=MAX_DESCRIPTION_CHARS)
        except ValueError as exc:
            raise PlantError(str(exc)) from None
        if not isinstance(self.n_states, int) or self.n_states < 1:
            raise PlantError(f"plant {self.name!r}: n_states must be an integer >= 1")
        for fname in ("f", "g", "h"):
            if not callable(getattr(self, fname)):
                raise PlantError(f"plant {self.name!r}: {fname} must be a function (x, p)")
        if not isinstance(self.params, Mapping):
            raise PlantError(f"plant {self.name!r}: params = {self.params!r}; allowed: a dict")
        values = {}
        for key, value in self.params.items():
            if not isinstance(key, str) or not key:
                raise PlantError(f"plant {self.name!r}: parameter name {key!r}; allowed: a name")
            try:  # the parameter named, not numpy's "could not convert string to float"
                values[key] = check_number(f"plant {self.name!r}: params[{key!r}]", value)
            except ValueError as exc:
                raise PlantError(str(exc)) from None
        object.__setattr__(self, "params", MappingProxyType(values))
        if not self.state_names:
            names = tuple(f"x{i}" for i in range(1, self.n_states + 1))
            object.__setattr__(self, "state_names", names)
        units = tuple(self.state_units) or ("",) * self.n_states
        if len(units) != self.n_states or not all(isinstance(v, str) for v in units):
            raise PlantError(
                f"plant {self.name!r}: state_units needs {self.n_states} strings (one per "
                f"state), got {len(units)}"
            )
        object.__setattr__(self, "state_units", units)
        for key in ("output_unit", "input_unit", "disturbance_unit"):
            if not isinstance(getattr(self, key), str):
                raise PlantError(f"plant {self.name!r}: {key} must be a string (e.g. 'rad')")
        try:  # names in Unicode NFKC (as expressions read them), distinct; units bounded
            params = normal_keys(f"plant {self.name!r}: params", self.params)
            state_names = tuple(
                check_name(f"plant {self.name!r}: state_names[{i}]", v)
                for i, v in enumerate(self.state_names)
            )
            check_distinct(f"plant {self.name!r}: state_names", state_names)
            for key in ("output_unit", "input_unit", "disturbance_unit"):
                check_text(
                    f"plant {self.name!r}: {key}", getattr(self, key), max_chars=MAX_UNIT_CHARS
                )
            for i, unit in enumerate(units):
                check_text(f"plant {self.name!r}: state_units[{i}]", unit, max_chars=MAX_UNIT_CHARS)
        except ValueError as exc:
            raise PlantError(str(exc)) from None
        object.__setattr__(self, "params", MappingProxyType(params))
        object.__setattr__(self, "state_names", state_names)
        if not isinstance(self.state_bounds, Mapping):
            raise PlantError(
                f"plant {self.name!r}: state_bounds must map state names to (low, high)"
            )
        bounds = {}
        for given, pair in self.state_bounds.items():
            key = normal_name(given) if isinstance(given, str) else given  # as declared
            if key not in self.state_names:
                raise PlantError(
                    f"plant {self.name!r}: state_bounds names {given!r}; allowed: one of the "
                    f"states {', '.join(self.state_names)}"
                )
            bounds[key] = _range_pair(f"plant {self.name!r}: state_bounds.{key}", pair)
        object.__setattr__(self, "state_bounds", MappingProxyType(bounds))
        if self.output_range is not None:
            pair = _range_pair(f"plant {self.name!r}: output_range", self.output_range)
            object.__setattr__(self, "output_range", pair)

    def bounds_array(self) -> NDArray[np.float64]:
        """The declared ranges as the engine reads them: (n + 1, 2) ``[low, high]`` rows,
        the states then the output, ``[-inf, inf]`` where none is declared."""
        out = np.empty((self.n_states + 1, 2))
        out[:, 0] = -np.inf
        out[:, 1] = np.inf
        for key, (lo, hi) in self.state_bounds.items():
            out[self.state_names.index(key)] = (lo, hi)
        if self.output_range is not None:
            out[self.n_states] = self.output_range
        return out

    def state_label(self, i: int) -> str:
        """Name and unit of state ``i`` (0-based), e.g. ``"theta [rad]"``."""
        return unit_label(self.state_names[i], self.state_units[i])

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
            for given, val in (source or {}).items():
                key = normal_name(given) if isinstance(given, str) else given  # as declared
                if key not in values:
                    raise PlantError(
                        f"plant {self.name!r} has no parameter {given!r}; "
                        f"allowed: {', '.join(self.param_names)}"
                    )
                values[key] = float(val) if op == "set" else values[key] * float(val)
        return np.array(list(values.values()), dtype=np.float64)

    # ------------------------------------------------------------------ evaluation
    def _real(self, out: Any, fname: str, x: ArrayLike) -> NDArray[np.float64]:
        """A function's result as a float array; PlantError if it holds complex numbers."""
        raw = np.asarray(out)
        if np.iscomplexobj(raw) or (
            raw.dtype == object and any(isinstance(v, complex) for v in raw.ravel())
        ):
            raise PlantError(
                f"plant {self.name!r}: {fname}(x, p) returns complex numbers at x = "
                f"{np.asarray(x, dtype=np.float64).tolist()}: {raw.tolist()}; return real floats "
                "(the engine's state is real; e.g. use math.sqrt of a nonnegative value)"
            )
        return np.asarray(raw, dtype=np.float64)

    def _vector(self, fn: PlantFunction, fname: str, x: ArrayLike, p: ArrayLike) -> np.ndarray:
        out = fn(np.asarray(x, dtype=np.float64), np.asarray(p, dtype=np.float64))
        if isinstance(out, tuple) and any(isinstance(v, (int, np.integer)) for v in out):
            raise PlantError(
                f"plant {self.name!r}: {fname}(x, p) returns an integer entry; return floats "
                "(write 0.0, not 0) so the compiled engine sees one element type"
            )
        arr = self._real(out, fname, x)
        if arr.shape != (self.n_states,):
            raise PlantError(
                f"plant {self.name!r}: {fname}(x, p) must return {self.n_states} floats "
                f"(one per state), got shape {arr.shape}"
            )
        return arr

    def rhs(self, x: ArrayLike, u: float, d: float = 0.0, p: ArrayLike | None = None) -> np.ndarray:
        r""":math:`\dot x = f(x,p) + g(x,p)u + b_d(x,p)\tau_d`, evaluated in Python.

        Parameters
        ----------
        x
            The state, n values.
        u
            The input.
        d
            The disturbance :math:`\tau_d` (default 0).
        p
            The parameter vector (default: the nominal one).

        Returns
        -------
        ndarray
            :math:`\dot x`, shape (n,).
        """
        pv = self.param_vector() if p is None else np.asarray(p, dtype=np.float64)
        dx = self._vector(self.f, "f", x, pv) + self._vector(self.g, "g", x, pv) * u
        if self.bd is not None and d != 0.0:
            dx = dx + self._vector(self.bd, "bd", x, pv) * d
        return dx

    def output(self, x: ArrayLike, p: ArrayLike | None = None) -> float:
        """:math:`y = h(x, p)`, evaluated in Python."""
        pv = self.param_vector() if p is None else np.asarray(p, dtype=np.float64)
        out = self._real(self.h(np.asarray(x, dtype=np.float64), pv), "h", x)
        if out.shape not in ((), (1,)):
            raise PlantError(
                f"plant {self.name!r}: h(x, p) must return one float, got shape {out.shape}"
            )
        return float(out.reshape(()))

    def check(self, x: ArrayLike | None = None) -> None:
        """Call every function once in Python; raise :class:`PlantError` naming the one at fault.

        Refused: a wrong shape, integer entries, complex numbers, a function that raises.
        Given ``x`` (the initial state of a run), f, g, h and b_d must also be finite there;
        without it they are called at x = (0.1, ..., 0.1) for their shapes only.
        """
        finite = x is not None
        x = np.full(self.n_states, 0.1) if x is None else np.asarray(x, dtype=np.float64)
        if x.shape != (self.n_states,):
            raise PlantError(f"plant {self.name!r}: x0 must have {self.n_states} entries")
        p = self.param_vector()
        for fname in ("f", "g", "h", "bd", "normal_form", "alpha_beta_of_xi", "state_of_xi"):
            fn = getattr(self, fname)
            if fn is None:
                continue
            try:
                if fname == "h":
                    val = np.asarray(self.output(x, p))
                elif fname in ("alpha_beta_of_xi", "state_of_xi"):
                    size = 2 if fname == "alpha_beta_of_xi" else self.n_states
                    out = self._real(fn(np.full(self.n_states, 0.1), p), fname, x)
                    if out.shape != (size,):
                        raise PlantError(
                            f"plant {self.name!r}: {fname}(xi, p) must return {size} floats; "
                            f"got shape {out.shape}"
                        )
                    continue  # functions of ξ: may be singular at x; only an observer uses it
                elif fname == "normal_form":
                    nf = self._real(fn(x, p), fname, x)
                    rho = self.relative_degree
                    if rho is None or nf.shape != (rho + 2,):
                        raise PlantError(
                            f"plant {self.name!r}: normal_form(x, p) must return ρ+2 floats "
                            f"(ξ_1..ξ_ρ, α, β) with relative_degree set; got shape {nf.shape}"
                        )
                    continue  # may be singular at x; only the IOFL law uses it
                else:
                    val = self._vector(fn, fname, x, p)
            except PlantError:
                raise
            except Exception as exc:  # a user function that raises on a valid state
                raise PlantError(
                    f"plant {self.name!r}: {fname}(x, p) failed at state x = {x.tolist()}: "
                    f"{type(exc).__name__}: {exc}"
                ) from exc
            if finite and not np.all(np.isfinite(val)):
                raise PlantError(
                    f"plant {self.name!r}: {fname}(x, p) = {val.tolist()} is not finite at the "
                    f"initial state x = {x.tolist()}; allowed: finite values"
                )

    def typecheck(self) -> None:
        """Compile every function with numba as the kernel calls it; PlantError naming the one
        numba cannot compile or whose result is not real floats.

        The arguments are C-contiguous float64 vectors (x, p).  f, g and b_d must return a
        tuple of n floats or a float vector, h one real number, the normal form a tuple or
        vector of floats.  Compiling here is not extra work when the kernel is then compiled
        (numba reuses these compilations); :mod:`aiofl.engine.build.instances` calls it for plants
        defined outside aiofl before compiling their kernel, or when that compilation fails.
        """
        from numba import types as nt
        from numba.core.errors import NumbaError

        sig = (nt.float64[::1], nt.float64[::1])
        names = ("f", "g", "h", "bd", "normal_form", "alpha_beta_of_xi")
        for fname, fn in zip(names, self.compiled, strict=True):
            try:
                fn.compile(sig)
            except NumbaError as exc:
                raise PlantError(
                    f"plant {self.name!r}: numba cannot compile {fname}(x, p): {_numba_reason(exc)}"
                ) from None
            ret = fn.overloads[sig].signature.return_type
            _check_return_type(self.name, fname, ret)

    # ------------------------------------------------------------------ compilation
    @cached_property
    def compiled(self) -> tuple[Any, Any, Any, Any, Any, Any]:
        """The numba-compiled ``(f, g, h, bd, normal_form, alpha_beta_of_xi)`` the engine's
        kernel calls (placeholders for the optional ones the plant lacks)."""
        from numba import njit

        self.check()
        nf = self.normal_form
        if nf is None:
            n = self.n_states

            def nf(x: NDArray[np.float64], p: NDArray[np.float64]) -> Any:  # placeholder
                return np.zeros(n + 2)

        ab = self.alpha_beta_of_xi or _no_alpha_beta

        def jit(fn: PlantFunction) -> Any:
            # the kernel's error model: x/0, overflow and domain errors give inf/NaN
            return njit(error_model="numpy")(getattr(fn, "py_func", fn))

        return (
            jit(self.f),
            jit(self.g),
            jit(self.h),
            jit(self.bd or _zero_bd),
            jit(nf),
            jit(ab),
        )


def _check_return_type(plant: str, fname: str, ret: Any) -> None:
    """PlantError unless numba type ``ret`` is what the kernel can use for ``fname``."""
    from numba import types as nt

    parts = list(ret.types) if isinstance(ret, nt.BaseTuple) else [getattr(ret, "dtype", ret)]
    if any(isinstance(t, nt.Complex) for t in parts):
        raise PlantError(
            f"plant {plant!r}: {fname}(x, p) returns complex numbers when compiled ({ret}); "
            "return real floats"
        )
    if fname == "h":
        ok = isinstance(ret, (nt.Float, nt.Integer))
        want = "one real number"
    else:
        ok = (isinstance(ret, nt.UniTuple) and isinstance(ret.dtype, nt.Float)) or (
            isinstance(ret, nt.Array) and ret.ndim == 1 and isinstance(ret.dtype, nt.Float)
        )
        want = "a tuple of floats or a float vector"
    if not ok:
        raise PlantError(
            f"plant {plant!r}: {fname}(x, p) returns {ret} when compiled; allowed: {want}"
        )


def _numba_reason(exc: Exception) -> str:
    """The informative line of a numba compile error, with its source location."""
    lines = [ln.strip() for ln in str(exc).splitlines() if ln.strip()]
    skip = ("Failed in", "During:", "File ", "<source", ">>>", "^")
    reason = next((ln for ln in lines if not ln.startswith(skip)), type(exc).__name__)
    where = next((ln.rstrip(":") for ln in lines if ln.startswith("File ")), "")
    return f"{type(exc).__name__}: {reason[:300]}" + (f" ({where})" if where else "")
