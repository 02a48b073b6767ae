r"""Symbolic plants: a SISO plant written in sympy, checked, analysed and compiled.

A :class:`SymbolicPlant` is the plant of the paper's Section III,

.. math:: \dot x = f(x) + g(x)u + b_d(x)\tau_d,\qquad y = h(x),

written in sympy (in Python, or as strings in a TOML file, see
:meth:`SymbolicPlant.from_dict`; strings are parsed by
:func:`aiofl.plants.expressions.parse_expression`, nothing is ``eval``-ed).  Its
:meth:`~SymbolicPlant.analyze` is :func:`aiofl.plants.normal_form.analyze` (relative degree
ρ, eq. 2; α, β and the normal-form coordinates ξ, eq. 3; zero dynamics), cached.

It compiles to the same fast :class:`aiofl.plants.base.Plant` the engine runs
(:meth:`SymbolicPlant.to_plant`): sympy generates plain Python source for
``f, g, h, bd`` and ``normal_form(x, p) -> (ξ_1..ξ_ρ, α, β)`` returning tuples of floats
(:mod:`aiofl.plants.codegen`), which numba compiles into the closed-loop kernel like any
hand-written plant.

This module imports sympy; nothing in the engine imports it.
"""

from __future__ import annotations

import hashlib
import math
import tomllib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import sympy as sp
from numpy.typing import NDArray
from sympy.core.function import AppliedUndef

from aiofl.limits import MAX_PLANT_FILE_BYTES
from aiofl.plants.base import Plant, unit_from_label
from aiofl.plants.codegen import GENERATED_FUNCTIONS, compile_sources, plant_sources
from aiofl.plants.expressions import (
    MAX_EXPANDED_TERMS,
    MAX_PARAMS,
    MAX_STATES,
    SymbolicPlantError,
    check_finite,
    expanded_terms,
    parse_expression,
)
from aiofl.plants.names import declared_symbols, normal_symbols, plant_text
from aiofl.plants.names import renamed as renamed_in
from aiofl.plants.normal_form import Analysis, RelativeDegreeError, analyze, drop_delta
from aiofl.plants.plant_modules import cached_plant, generator_digest, plant_from_sources
from aiofl.text import (
    MAX_DESCRIPTION_CHARS,
    MAX_UNIT_CHARS,
    check_text,
    normal_name,
)

__all__ = ["SymbolicPlant", "read_plant_toml"]


@dataclass(frozen=True, eq=False)
class SymbolicPlant:
    r"""A SISO plant :math:`\dot x = f(x) + g(x)u + b_d(x)\tau_d`, :math:`y = h(x)` in sympy.

    Parameters
    ----------
    name
        Identifier (the engine plant built by :meth:`to_plant` gets this name).
    states
        State symbols :math:`x_1..x_n` (real).
    params
        Ordered ``(symbol, nominal value)`` pairs; the order is that of the parameter vector
        ``p`` of the compiled plant.
    f, g, bd
        Column vectors of n expressions (``bd`` may be None: no disturbance input).
    h
        Output expression; must depend on the state.
    eta
        Optional internal coordinates φ(x) (n − ρ expressions with
        :math:`\partial\phi/\partial x\, g = 0`, eq. 3); found automatically when g has a
        constant direction.
    equilibrium
        Optional point :math:`x_e` for the zero-dynamics stability check; otherwise x = 0 is
        tried, then a numerical root of :math:`\xi(x) = 0,\ \dot\eta(x) = 0`.
    state_labels, description
        Documentation (one label per state, e.g. ``"hub angle θ [rad]"``).
    output_unit, input_unit, disturbance_unit, state_units
        Units of y, u, τ_d and of each state (plain text, ``""`` when not declared); a state
        without a declared unit takes the one in its label's brackets (``"... [rad]"``).
        Passed on to :meth:`to_plant` for figures, CSV headers and tables.
    """

    name: str
    states: tuple[Any, ...]
    params: tuple[tuple[Any, float], ...]
    f: Any
    g: Any
    h: Any
    bd: Any = None
    eta: tuple[Any, ...] | None = None
    equilibrium: tuple[float, ...] | None = None
    state_labels: tuple[str, ...] = ()
    description: str = ""
    output_unit: str = ""
    input_unit: str = ""
    disturbance_unit: str = ""
    state_units: tuple[str, ...] = ()
    state_bounds: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    output_range: tuple[float, float] | None = None
    _cache: dict[str, Any] = field(default_factory=dict, repr=False)

    def __post_init__(self) -> None:
        plant_text(check_text, "name", self.name)
        name = self.name
        plant_text(
            check_text,
            f"plant {name!r}: description",
            self.description,
            max_chars=MAX_DESCRIPTION_CHARS,
        )
        states = tuple(self.states)
        if not states:
            raise SymbolicPlantError(f"plant {name!r}: states must list at least one state")
        if len(set(states)) != len(states):
            raise SymbolicPlantError(f"plant {name!r}: states must be distinct")
        _check_counts(name, len(states), len(self.params))
        # symbols named in Unicode NFKC, as a parsed expression reads names: a sympy
        # symbol from Python named otherwise ("ﬁ") is renamed ("fi") wherever it is used
        renamed = normal_symbols(name, states, [s for s, _ in self.params])
        if renamed:
            states = tuple(renamed.get(s, s) for s in states)
            object.__setattr__(
                self, "params", tuple((renamed.get(s, s), v) for s, v in self.params)
            )
            for key in ("f", "g", "h", "bd", "eta"):
                object.__setattr__(self, key, renamed_in(getattr(self, key), renamed))
        params = tuple((s, _finite(v, f"plant {name!r}: params.{s}")) for s, v in self.params)
        psyms = {s for s, _ in params}
        if len(psyms) != len(params):
            raise SymbolicPlantError(f"plant {name!r}: parameter names must be distinct")
        clash = psyms & set(states)
        if clash:
            raise SymbolicPlantError(
                f"plant {name!r}: {', '.join(map(str, clash))} is both a state and a parameter"
            )
        n = len(states)
        object.__setattr__(self, "states", states)
        object.__setattr__(self, "params", params)
        allowed = set(states) | psyms
        by_name = {str(s): s for s in allowed}
        vecs: dict[str, Any] = {}
        for fname in ("f", "g", "bd"):
            val = getattr(self, fname)
            if val is None:
                if fname != "bd":
                    raise SymbolicPlantError(f"plant {name!r}: {fname} is required")
                continue
            entries = list(val)
            if len(entries) != n:
                raise SymbolicPlantError(
                    f"plant {name!r}: {fname} has {len(entries)} entries; the plant has n = {n} "
                    f"states ({', '.join(map(str, states))}), so {fname} needs {n}"
                )
            vecs[fname] = sp.ImmutableMatrix(
                [_expression(e, by_name, f"{fname}[{i}]") for i, e in enumerate(entries, 1)]
            )
        if isinstance(self.h, (list, tuple, sp.MatrixBase)):
            raise SymbolicPlantError(f"plant {name!r}: h must be one scalar expression (SISO)")
        h = _expression(self.h, by_name, "h")
        for fname, expr in (*vecs.items(), ("h", h)):
            free = expr.free_symbols - allowed
            if free:
                raise SymbolicPlantError(
                    f"plant {name!r}: {fname} uses unknown symbol(s) "
                    f"{', '.join(sorted(map(str, free)))}; allowed: states and params"
                )
            if expr.atoms(AppliedUndef):
                raise SymbolicPlantError(f"plant {name!r}: {fname} uses an undefined function")
        if not (h.free_symbols & set(states)):
            raise SymbolicPlantError(
                f"plant {name!r}: h = {h} is not a function of the state x "
                f"({', '.join(map(str, states))}); the output must depend on x"
            )
        if all(e == 0 for e in vecs["g"]):
            raise RelativeDegreeError(
                f"plant {name!r}: g(x) ≡ 0, the input u does not enter the plant; the relative "
                "degree is undefined"
            )
        object.__setattr__(self, "f", vecs["f"])
        object.__setattr__(self, "g", vecs["g"])
        object.__setattr__(self, "bd", vecs.get("bd"))
        object.__setattr__(self, "h", h)
        if self.eta is not None:
            eta = tuple(_expression(e, by_name, f"eta[{i}]") for i, e in enumerate(self.eta, 1))
            for i, e in enumerate(eta, 1):
                if e.free_symbols - allowed:
                    raise SymbolicPlantError(f"plant {name!r}: eta[{i}] uses unknown symbols")
            object.__setattr__(self, "eta", eta)
        if self.equilibrium is not None:
            eq = tuple(
                _finite(v, f"plant {name!r}: equilibrium[{i}]")
                for i, v in enumerate(self.equilibrium, 1)
            )
            if len(eq) != n:
                raise SymbolicPlantError(
                    f"plant {name!r}: equilibrium has {len(eq)} entries; the plant has {n} states"
                )
            object.__setattr__(self, "equilibrium", eq)
        labels = tuple(self.state_labels) or tuple(str(s) for s in states)
        if len(labels) != n:
            raise SymbolicPlantError(f"plant {name!r}: state_labels needs {n} entries")
        for i, lab in enumerate(labels, 1):
            plant_text(check_text, f"plant {name!r}: the label of state {i}", lab)
        object.__setattr__(self, "state_labels", labels)
        from_labels = tuple(unit_from_label(lab)[:MAX_UNIT_CHARS] for lab in labels)
        units = tuple(self.state_units) or from_labels
        if len(units) != n or not all(isinstance(u, str) for u in units):
            raise SymbolicPlantError(
                f"plant {name!r}: state_units needs {n} strings (one per state)"
            )
        object.__setattr__(self, "state_units", units)
        for key in ("output_unit", "input_unit", "disturbance_unit", "state_units"):
            val = getattr(self, key)
            many = key == "state_units"
            for i, v in enumerate(val if many else (val,), 1):
                field = f"plant {name!r}: {key}" + (f"[{i}]" if many else "")
                plant_text(check_text, field, v, max_chars=MAX_UNIT_CHARS)

    # ------------------------------------------------------------- constructors
    @classmethod
    def from_strings(
        cls,
        name: str,
        states: Sequence[str] | Mapping[str, str],
        params: Mapping[str, float],
        f: Sequence[str],
        g: Sequence[str],
        h: str,
        bd: Sequence[str] | None = None,
        eta: Sequence[str] | None = None,
        equilibrium: Sequence[float] | None = None,
        description: str = "",
        output_unit: str = "",
        input_unit: str = "",
        disturbance_unit: str = "",
        state_units: Sequence[str] | Mapping[str, str] | None = None,
        bounds: Mapping[str, Sequence[float]] | None = None,
        output_range: Sequence[float] | None = None,
    ) -> SymbolicPlant:
        """Build a plant from expression strings (parsed by :mod:`aiofl.plants.expressions`).

        ``states`` is a list of names or a mapping name -> label; ``params`` maps names to
        nominal values; ``state_units`` is a list of n units or a mapping state -> unit;
        ``bounds`` maps state names to their physical ``[low, high]`` and ``output_range``
        is the output's (:attr:`aiofl.plants.base.Plant.state_bounds`: a run that leaves
        one is lost).
        """
        if isinstance(states, str) or not isinstance(states, (Sequence, Mapping)):
            raise SymbolicPlantError(f"plant {name!r}: states must be a list of names")
        labels = list(states.values()) if isinstance(states, Mapping) else []
        names = list(states)
        if not isinstance(params, Mapping):
            raise SymbolicPlantError(f"plant {name!r}: params must be a table name = value")
        plant_text(check_text, "name", name)
        _check_counts(name, len(names), len(params))
        # every name in Unicode NFKC, the form Python's parser gives the names in the
        # expressions ("-ﬁ*theta" reads fi): declared "fi" and "ﬁ" are one name, refused
        symbols, normal = declared_symbols(name, names, list(params))
        for pn, pv in params.items():
            if isinstance(pv, bool) or not isinstance(pv, (int, float)):
                raise SymbolicPlantError(
                    f"plant {name!r}: params.{pn} = {pv!r}; allowed: a finite number"
                )

        def vec(key: str, val: Any) -> list[Any]:
            if isinstance(val, str) or not isinstance(val, Sequence):
                raise SymbolicPlantError(
                    f"plant {name!r}: {key} must be a list of {len(names)} expression strings"
                )
            if key != "eta" and len(val) != len(names):  # before parsing any entry
                raise SymbolicPlantError(
                    f"plant {name!r}: {key} has {len(val)} entries; the plant has n = "
                    f"{len(names)} states ({', '.join(names)}), so {key} needs {len(names)}"
                )
            if len(val) > len(names):
                raise SymbolicPlantError(
                    f"plant {name!r}: {key} has {len(val)} entries; allowed: at most n − ρ < "
                    f"{len(names)}"
                )
            return [parse_expression(s, symbols, f"{key}[{i}]") for i, s in enumerate(val, 1)]

        if equilibrium is not None and (
            isinstance(equilibrium, str) or not isinstance(equilibrium, Sequence)
        ):
            raise SymbolicPlantError(
                f"plant {name!r}: equilibrium must be a list of {len(names)} numbers"
            )
        return cls(
            name=name,
            states=tuple(symbols[normal[s]] for s in names),
            params=tuple((symbols[normal[p]], v) for p, v in params.items()),
            f=vec("f", f),
            g=vec("g", g),
            h=parse_expression(h, symbols, "h") if not isinstance(h, (list, tuple)) else h,
            bd=None if bd is None else vec("bd", bd),
            eta=None if eta is None else tuple(vec("eta", eta)),
            equilibrium=None if equilibrium is None else tuple(equilibrium),
            state_labels=tuple(str(v) for v in labels),
            description=description,
            output_unit=output_unit,
            input_unit=input_unit,
            disturbance_unit=disturbance_unit,
            state_units=_state_units(name, [normal[s] for s in names], state_units),
            state_bounds=_bounds(name, [normal[s] for s in names], bounds),
            output_range=(
                None if output_range is None else _pair(name, "output_range", output_range)
            ),
        )

    _KEYS = frozenset(
        {"name", "description", "states", "params", "f", "g", "h", "bd", "eta", "equilibrium"}
        | {"output_unit", "input_unit", "disturbance_unit", "state_units"}
        | {"bounds", "output_range"}
    )

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], source: str = "<dict>") -> SymbolicPlant:
        """Build a plant from a dict with the keys of the TOML format.

        .. code-block:: toml

            name = "pendulum"
            description = "damped pendulum"
            states = ["theta", "omega"]          # or a [states] table: theta = "angle [rad]"
            f = ["omega", "-g/l*sin(theta) - c/(m*l**2)*omega"]
            g = ["0", "1/(m*l**2)"]
            h = "theta"
            bd = ["0", "1/(m*l**2)"]             # optional disturbance input
            # eta = ["..."]                      # optional internal coordinates (eq. 3)
            # equilibrium = [0.0, 0.0]           # optional point for the zero dynamics
            output_unit = "rad"                  # optional units (text), for figures, CSV
            input_unit = "N·m"                   #   headers and tables; states take the
            state_units = ["rad", "rad/s"]       #   units in their labels' [brackets]
            # disturbance_unit = "N·m"
            # output_range = [-3.2, 3.2]         # optional physical ranges: a run that
            [params]                             #   leaves one is *lost*
            m = 1.0
            l = 0.5
            c = 0.1
            g = 9.81
            [bounds]                             # optional: states' [low, high]
            theta = [-3.2, 3.2]

        (Top-level keys must come before the ``[params]`` table in TOML.)
        """
        unknown = sorted(set(data) - cls._KEYS)
        if unknown:
            raise SymbolicPlantError(
                f"{source}: unknown key(s) {', '.join(unknown)}; allowed: "
                f"{', '.join(sorted(cls._KEYS))}"
            )
        missing = [k for k in ("states", "params", "f", "g", "h") if k not in data]
        if missing:
            raise SymbolicPlantError(f"{source}: missing key(s) {', '.join(missing)}")
        name = str(data.get("name", Path(source).stem if source != "<dict>" else "symbolic"))
        return cls.from_strings(
            name=name,
            states=data["states"],
            params=data["params"],
            f=data["f"],
            g=data["g"],
            h=data["h"],
            bd=data.get("bd"),
            eta=data.get("eta"),
            equilibrium=data.get("equilibrium"),
            description=str(data.get("description", "")),
            output_unit=data.get("output_unit", ""),
            input_unit=data.get("input_unit", ""),
            disturbance_unit=data.get("disturbance_unit", ""),
            state_units=data.get("state_units"),
            bounds=data.get("bounds"),
            output_range=data.get("output_range"),
        )

    @classmethod
    def from_toml(cls, path: str | Path) -> SymbolicPlant:
        """Read a plant from a TOML file (format of :meth:`from_dict`)."""
        return cls.from_dict(read_plant_toml(path), str(path))

    # ----------------------------------------------------------------- helpers
    @property
    def n(self) -> int:
        """Number of states n."""
        return len(self.states)

    @property
    def param_symbols(self) -> tuple[Any, ...]:
        """Parameter symbols, in the order of the vector ``p``."""
        return tuple(s for s, _ in self.params)

    @property
    def nominal(self) -> dict[Any, float]:
        """Nominal parameter values by symbol."""
        return dict(self.params)

    def numeric(self, exprs: Sequence[Any]) -> Any:
        """A numpy function ``x -> array`` of ``exprs`` at the nominal parameters."""
        sub = [drop_delta(sp.sympify(e)).subs(self.nominal) for e in exprs]
        fn = sp.lambdify([self.states], sub, modules="numpy")

        def call(x: Any) -> NDArray[np.float64]:
            with np.errstate(all="ignore"):
                out = np.asarray(fn(np.asarray(x, dtype=np.float64)))
            if np.iscomplexobj(out):  # a complex value (sqrt of a negative number) is NaN
                out = np.where(out.imag == 0, out.real, np.nan)
            return np.asarray(out, dtype=np.float64)

        return call

    def analyze(self) -> Analysis:
        """The Section-III analysis (cached): :func:`aiofl.plants.normal_form.analyze`."""
        if "analysis" not in self._cache:
            self._cache["analysis"] = analyze(self)
        return self._cache["analysis"]

    # ----------------------------------------------------------- code generation
    def function_sources(self, prefix: str = "") -> dict[str, str]:
        """Python source of ``f, g, h, bd, normal_form`` (``def <prefix><name>(x, p)``).

        Each returns a tuple of floats (``h`` one float); integer constants are written as
        floats so numba sees homogeneous tuples (:meth:`aiofl.plants.base.Plant.check`).
        ``normal_form`` returns :math:`(\\xi_1..\\xi_\\rho, \\alpha, \\beta)` with common
        subexpressions shared (:func:`aiofl.plants.codegen.plant_sources`).
        """
        if "sources" not in self._cache:
            self._cache["sources"] = plant_sources(self, self.analyze())
        srcs: dict[str, str] = self._cache["sources"]
        return {k: v.replace("def _fn_", f"def {prefix}", 1) for k, v in srcs.items()}

    def compile_functions(self) -> dict[str, Any]:
        """The generated functions, executed into a namespace with only ``math``."""
        if "functions" not in self._cache:
            self._cache["functions"] = compile_sources(self.function_sources(), self.name)
        return dict(self._cache["functions"])

    def to_plant(self, name: str | None = None, *, cache: bool = True) -> Plant:
        """Compile to an engine :class:`aiofl.plants.base.Plant` (with ``normal_form`` for IOFL).

        The generated functions are plain Python over ``math``, so the engine's numba kernel
        compiles them exactly as it compiles hand-written plants.  With ``cache`` (and the
        cache on, :mod:`aiofl.cache`) the plant is built once: its module is written into
        the cache under :meth:`definition_key` (:mod:`aiofl.plants.plant_modules`), and a
        later process imports it from there without the symbolic analysis, with the kernel
        compiled for its functions cached on disk too; otherwise the functions live in
        memory only.
        """
        if not cache:
            return self._plant_in_memory(name)
        key = self.definition_key(name)
        hit = cached_plant(key)
        if hit is not None:
            return hit
        return plant_from_sources(self.module_functions(), self._plant_in_memory(name), key)

    def definition_key(self, name: str | None = None) -> str:
        """A digest of everything the plant built by :meth:`to_plant` (with ``name``) follows
        from: this definition (expressions by ``sympy.srepr``, parameter values, units,
        labels, ...) and the code that analyses it and generates its functions."""
        srepr = sp.srepr
        eta = None if self.eta is None else tuple(srepr(e) for e in self.eta)
        parts = (
            name or self.name,
            tuple(srepr(s) for s in self.states),
            tuple((srepr(s), float(v)) for s, v in self.params),
            srepr(self.f),
            srepr(self.g),
            srepr(self.h),
            None if self.bd is None else srepr(self.bd),
            eta,
            self.equilibrium,
            self.state_labels,
            self.description,
            self.output_unit,
            self.input_unit,
            self.disturbance_unit,
            self.state_units,
            tuple(sorted(self.state_bounds.items())),
            self.output_range,
        )
        text = f"{generator_digest()}|{parts!r}"
        return "py_" + hashlib.sha256(text.encode()).hexdigest()[:24]

    def module_functions(self) -> list[str]:
        """The generated functions as a plant module holds them (``def _fn_f(x, p)``, ...,
        in the order of :data:`aiofl.plants.codegen.GENERATED_FUNCTIONS`)."""
        srcs = self.function_sources(prefix="_fn_")
        return [srcs[k] for k in GENERATED_FUNCTIONS if k in srcs]

    def _plant_in_memory(self, name: str | None) -> Plant:
        """The :class:`Plant` with the generated functions executed in memory."""
        fns = self.compile_functions()
        return Plant(
            name=name or self.name,
            n_states=self.n,
            f=fns["f"],
            g=fns["g"],
            h=fns["h"],
            bd=fns.get("bd"),
            params={str(s): v for s, v in self.params},
            relative_degree=self.analyze().rho,
            normal_form=fns["normal_form"],
            alpha_beta_of_xi=fns.get("alpha_beta_of_xi"),
            state_of_xi=fns.get("state_of_xi"),
            state_names=tuple(str(s) for s in self.states),
            description=self.description,
            output_unit=self.output_unit,
            input_unit=self.input_unit,
            state_units=self.state_units,
            disturbance_unit=self.disturbance_unit,
            state_bounds=self.state_bounds,
            output_range=self.output_range,
        )


def _pair(name: str, key: str, value: Any) -> tuple[float, float]:
    """A ``[low, high]`` of numbers with low < high (±inf leaves a side open)."""
    ok = isinstance(value, Sequence) and not isinstance(value, str) and len(value) == 2
    ok = ok and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)
    if not ok or not float(value[0]) < float(value[1]) or math.isnan(float(value[0])):
        raise SymbolicPlantError(
            f"plant {name!r}: {key} = {value!r:.60}; allowed: [low, high], two numbers with "
            "low < high (inf leaves a side open)"
        )
    return float(value[0]), float(value[1])


def _bounds(name: str, states: Sequence[str], table: Any) -> dict[str, tuple[float, float]]:
    """The TOML table ``[bounds]``: state name -> ``[low, high]``."""
    if table is None:
        return {}
    if not isinstance(table, Mapping):
        raise SymbolicPlantError(f"plant {name!r}: bounds must be a table: state = [low, high]")
    out = {}
    for given, value in table.items():
        key = normal_name(given) if isinstance(given, str) else given  # as the states are read
        if key not in states:
            raise SymbolicPlantError(
                f"plant {name!r}: bounds.{key!s:.40}; allowed: a state name ({', '.join(states)})"
            )
        out[key] = _pair(name, f"bounds.{key}", value)
    return out


def _state_units(
    name: str, states: Sequence[str], units: Sequence[str] | Mapping[str, str] | None
) -> tuple[str, ...]:
    """The TOML key ``state_units``: a list of n strings or a table state -> unit."""
    if units is None:
        return ()  # SymbolicPlant takes them from the labels' brackets
    if isinstance(units, Mapping):
        units = {normal_name(k) if isinstance(k, str) else k: v for k, v in units.items()}
        unknown = sorted(map(str, set(units) - set(states)))
        if unknown:
            raise SymbolicPlantError(
                f"plant {name!r}: state_units names unknown state(s) {', '.join(unknown)}; "
                f"allowed: {', '.join(states)}"
            )
        units = [units.get(s, "") for s in states]
    if isinstance(units, str) or not isinstance(units, Sequence):
        raise SymbolicPlantError(
            f"plant {name!r}: state_units must be a list of {len(states)} strings or a table"
        )
    if len(units) != len(states) or not all(isinstance(u, str) for u in units):
        raise SymbolicPlantError(
            f"plant {name!r}: state_units = {list(units)!r}; allowed: {len(states)} strings, "
            "one per state"
        )
    return tuple(units)


def _check_counts(name: str, n_states: int, n_params: int) -> None:
    """Refuse more than :data:`~aiofl.plants.expressions.MAX_STATES` states or
    :data:`~aiofl.plants.expressions.MAX_PARAMS` parameters (before any is parsed)."""
    if n_states > MAX_STATES:
        raise SymbolicPlantError(
            f"plant {name!r}: states lists {n_states} states; allowed: at most {MAX_STATES} "
            "(the symbolic analysis takes n Lie derivatives over n states)"
        )
    if n_params > MAX_PARAMS:
        raise SymbolicPlantError(
            f"plant {name!r}: params lists {n_params} parameters; allowed: at most {MAX_PARAMS}"
        )


def _finite(value: Any, where: str) -> float:
    """``value`` as a finite float, or a SymbolicPlantError naming ``where``."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)):
        try:
            value = float(sp.sympify(value, strict=True))  # a sympy number from Python
        except (sp.SympifyError, TypeError, ValueError):
            raise SymbolicPlantError(f"{where} = {value!r:.40}; allowed: a finite number") from None
    try:
        out = float(value)
    except OverflowError:
        out = math.inf
    if not math.isfinite(out):
        raise SymbolicPlantError(f"{where} = {value!r:.40}; allowed: a finite number")
    return out


def _expression(value: Any, symbols: Mapping[str, Any], where: str) -> Any:
    """One entry of f, g, h, b_d or η: a string is parsed (:func:`parse_expression`, with
    its bounds); a sympy expression or number from Python is held to the same bounds on
    its finite constants and expanded size."""
    if isinstance(value, str):
        return parse_expression(value, symbols, where)
    try:
        expr = sp.sympify(value, strict=True)
    except (sp.SympifyError, TypeError, ValueError):
        raise SymbolicPlantError(f"{where}: {value!r:.60} is not an expression") from None
    if not isinstance(expr, sp.Expr):
        raise SymbolicPlantError(f"{where}: {value!r:.60} is not a scalar expression")
    check_finite(expr, where)
    terms = expanded_terms(expr)
    if terms > MAX_EXPANDED_TERMS:
        raise SymbolicPlantError(
            f"{where}: the expanded form would have about {terms:.3g} terms; allowed: at most "
            f"{MAX_EXPANDED_TERMS}"
        )
    return expr


def read_plant_toml(path: str | Path) -> dict[str, Any]:
    """The TOML table of a plant file; a missing, oversized or malformed file is a
    SymbolicPlantError."""
    p = Path(path)
    if not p.is_file():
        raise SymbolicPlantError(f"plant file {str(p)!r} does not exist")
    size = p.stat().st_size
    if size > MAX_PLANT_FILE_BYTES:
        raise SymbolicPlantError(
            f"plant file {str(p)!r} has {size} bytes; allowed: at most {MAX_PLANT_FILE_BYTES} "
            f"({MAX_STATES} states x 4 vectors of expressions fit in a fraction of it)"
        )
    try:
        return tomllib.loads(p.read_text(encoding="utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise SymbolicPlantError(f"malformed TOML in {p}: {exc}") from None
