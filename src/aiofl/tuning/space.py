r"""The ``[tune]`` table: settings, search space, objective, and writing a tuned config.

.. code-block:: toml

    [tune]
    algorithm = "ga"          # ga | de | cmaes | nsga2 (pymoo)
    objective = "opi"         # opi | itae | iae | ise | isu | iau | {itae = 1.0, isu = 0.01}
    t_final = 6.0             # tuning horizon [s] (paper: 6 s); default: the scenario's
    population = 64
    generations = 50
    seed = 1
    divergence_penalty = 1e6  # objective of a member that diverged (see below)
    robust = { draws = 16, aggregate = "cvar", alpha = 0.9, corners = true }  # optional;
                              # needs [uncertainty]; corners: also the 2^k box corners
    noise_realisations = 1    # K > 1: a noisy measurement scored over K noise realisations
    omega0_ceiling = false    # true: eso.omega0's hi clipped to the rig's omega0 ceiling
                              # (aiofl.tuning.ceiling; aiofl tune --omega0-ceiling)
    # nsga2 only: objectives (2 or 3) and constraints, see aiofl.tuning.objective
    # objectives = ["itae", "isu"]          # METRIC or METRIC:AGGREGATE
    # constraints = ["isu <= 15.5", "stable_fraction >= 1"]
    # choose = "best-first-under-constraints"   # or "knee" (aiofl.tuning.front)
    [tune.parameters]
    "eso.omega0" = { lo = 10.0, hi = 2000.0, log = true }
    "law.b0" = { lo = 1.0, hi = 1e5, log = true }
    # with [controller.eso] gains = "kalman": the noise intensity instead of omega0
    # "eso.q" = { lo = 1e6, hi = 1e20, log = true }

Parameter names are the engine's column names (:data:`aiofl.layout.FLOAT_COLUMNS`); the
rest of the controller stays as the config's ``[controller]`` table sets it (e.g.
``alpha = "binomial"`` there keeps Gao's fixed ratios while ω0 is tuned).  With Kalman
observer gains (``[controller.eso] gains = "kalman"``) ω0 and α are derived: tune
``eso.q`` (and/or ``eso.r``) instead, log-scaled like ω0 (ω0 = (q/r)^{1/(2ρ+2)}, so a
log-uniform q is a log-uniform equivalent bandwidth).  Each bound must
lie in the range the config schema allows for that field, and a parameter must act on
the configured structure (tuning ``td.R`` of a linear prefilter is rejected).

The search runs in the unit cube: coordinate :math:`s\in[0,1]` maps to
:math:`lo + s(hi-lo)`, or to :math:`lo\,(hi/lo)^s` with ``log = true``.

The objective (one, or NSGA-II's objectives and constraints) and its penalty for a member
that diverges are :mod:`aiofl.tuning.objective`'s.

With a noisy measurement (``[sensor]`` or ``[scenario]`` noise) ``noise_realisations = K``
scores every candidate over K noise sequences, the same K for every candidate (common
random numbers; realisation 0 is the config's noise seed, the others
:func:`aiofl.scenario.realisation_seed`): a candidate's metrics are their mean over the K
realisations (a candidate that diverges on any is diverged), so the linear objective is the
mean cost; with ``robust`` every draw gets its K realisations and the robust aggregate
runs over the draws of these means (:mod:`aiofl.tuning.objective`).
"""

from __future__ import annotations

import copy
import math
from collections.abc import Iterable, Mapping
from typing import TYPE_CHECKING, Annotated, Any, Literal

import numpy as np
from numpy.typing import NDArray
from pydantic import Field, ValidationError, field_validator, model_validator

from aiofl import layout as L
from aiofl.limits import DT_MAX, MAX_EVALUATIONS, MAX_POPULATION, T_FINAL_MAX
from aiofl.table_model import TableModel

if TYPE_CHECKING:  # pragma: no cover
    from aiofl.controller import Controller

__all__ = [
    "ParameterBounds",
    "RobustSettings",
    "SearchSpace",
    "TuneSettings",
    "config_with_values",
    "parse_tune_settings",
    "to_toml",
    "update_toml",
    "used_parameters",
]

ALGORITHMS = ("ga", "de", "cmaes", "nsga2")
#: largest ``robust.draws`` (each candidate costs K + 1 simulations)
MAX_ROBUST_DRAWS = 1000
#: largest ``noise_realisations`` (each candidate costs K simulations per plant)
MAX_NOISE_REALISATIONS = 256


class ParameterBounds(TableModel):
    """Search interval of one parameter: ``lo <= value <= hi``, optionally log-scaled."""

    lo: Annotated[float, Field(allow_inf_nan=False)]
    hi: Annotated[float, Field(allow_inf_nan=False)]
    log: bool = False

    @model_validator(mode="after")
    def _order(self) -> ParameterBounds:
        if not self.lo < self.hi:
            raise ValueError(f"bounds reversed or empty: lo = {self.lo} must be < hi = {self.hi}")
        if self.log and not self.lo > 0:
            raise ValueError(f"log = true needs lo > 0 (got lo = {self.lo})")
        return self


class RobustSettings(TableModel):
    """``robust = { draws = K, aggregate = "mean" | "worst" | "cvar", alpha = 0.9,
    corners = false }``.

    ``corners = true`` adds the corners of the ``[uncertainty]`` box
    (:func:`aiofl.uncertainty.corner_draws`: :math:`2^k` plants for k <= 12 drawn
    quantities) to the K random draws, so a candidate is scored on K + 2^k + 1 plants; the
    extremes of the true plant's input gain β sit at the corners, where random draws rarely
    go (:mod:`aiofl.analysis.corners`).  Recommended for new recipes.  The default stays
    false so that the shipped presets' ``[tune]`` tables, written before the option
    existed, keep reproducing their shipped values.
    """

    draws: Annotated[int, Field(ge=1, le=MAX_ROBUST_DRAWS)]
    aggregate: Literal["mean", "worst", "cvar"] = "mean"
    alpha: Annotated[float, Field(gt=0, lt=1, allow_inf_nan=False)] = 0.9
    corners: bool = False


class TuneSettings(TableModel):
    """Validated ``[tune]`` table (see the module docstring for the fields)."""

    algorithm: Literal["ga", "de", "cmaes", "nsga2"] = "ga"
    objective: str | dict[str, Annotated[float, Field(ge=0, allow_inf_nan=False)]] = "opi"
    # None: the scenario's horizon (:meth:`with_horizon`); never longer than it
    t_final: Annotated[float, Field(gt=0, le=T_FINAL_MAX, allow_inf_nan=False)] | None = None
    population: Annotated[int, Field(ge=2, le=MAX_POPULATION)] = 64
    generations: Annotated[int, Field(ge=1, le=MAX_EVALUATIONS // 2)] = 50
    seed: Annotated[int, Field(ge=0, lt=2**32)] = 1
    divergence_penalty: Annotated[float, Field(gt=0, le=1e300, allow_inf_nan=False)] = 1e6
    include_initial: bool = True
    dt: Annotated[float, Field(gt=0, le=DT_MAX, allow_inf_nan=False)] | None = None
    method: Literal["rk4", "euler"] | None = None
    chunks: Annotated[int, Field(ge=1, le=100_000)] | None = None
    parameters: dict[str, ParameterBounds]
    robust: RobustSettings | None = None
    noise_realisations: Annotated[int, Field(ge=1, le=MAX_NOISE_REALISATIONS)] = 1
    objectives: list[str] | None = None
    constraints: list[str] = Field(default_factory=list, max_length=16)
    choose: Literal["best-first-under-constraints", "knee"] = "best-first-under-constraints"
    omega0_ceiling: bool = False

    @field_validator("objectives")
    @classmethod
    def _objectives(cls, v: list[str] | None) -> list[str] | None:
        from aiofl.tuning.objective import parse_quantity

        if v is None:
            return v
        if not 2 <= len(v) <= 3:
            raise ValueError(f"objectives has {len(v)} entries; allowed: 2 or 3")
        parsed = [parse_quantity(q) for q in v]
        if any(q.metric == "stable_fraction" for q in parsed):
            raise ValueError("stable_fraction is not an objective; use it as a constraint")
        texts = [q.text() for q in parsed]
        if len(set(texts)) != len(texts):
            raise ValueError(f"objectives repeat a quantity: {v}")
        return v

    @field_validator("constraints")
    @classmethod
    def _constraints(cls, v: list[str]) -> list[str]:
        from aiofl.tuning.objective import parse_constraint

        for c in v:
            parse_constraint(c)
        return v

    @model_validator(mode="after")
    def _budget(self) -> TuneSettings:
        if self.algorithm == "nsga2" and self.objectives is None:
            raise ValueError('algorithm = "nsga2" needs objectives, e.g. ["itae", "isu"]')
        if self.algorithm != "nsga2" and (self.objectives is not None or self.constraints):
            raise ValueError(
                f'objectives and constraints need algorithm = "nsga2" (got {self.algorithm!r}; '
                "the single-objective algorithms use objective)"
            )
        if self.robust is None:
            from aiofl.tuning.objective import parse_constraint, parse_quantity

            named = [parse_quantity(q) for q in self.objectives or ()]
            named += [parse_constraint(c).quantity for c in self.constraints]
            over = [q.text() for q in named if q.aggregate not in (None, "nominal")]
            if over:
                raise ValueError(
                    f"{', '.join(over)}: an aggregate over draws needs robust = "
                    "{ draws = K, ... } (and an [uncertainty] table)"
                )
        k1 = (1 + (self.robust.draws if self.robust else 0)) * self.noise_realisations
        if self.population * k1 > MAX_POPULATION:
            raise ValueError(
                f"population x (robust.draws + 1) x noise_realisations = {self.population} x "
                f"{k1} = {self.population * k1} members per generation; allowed: at most "
                f"{MAX_POPULATION} (one batched engine call)"
            )
        total = self.population * self.generations
        if total > MAX_EVALUATIONS:
            raise ValueError(
                f"population x generations = {self.population} x {self.generations} = "
                f"{total} evaluations; allowed: at most {MAX_EVALUATIONS} (every member is "
                "kept and written to evaluations.csv)"
            )
        return self

    @field_validator("objective")
    @classmethod
    def _objective(cls, v: str | dict[str, float]) -> str | dict[str, float]:
        allowed = ("opi", *L.METRIC_NAMES)
        if isinstance(v, str):
            if v not in allowed:
                raise ValueError(f"objective {v!r}; allowed: {', '.join(allowed)} or a table")
            return v
        if not v:
            raise ValueError("objective table is empty; give weights such as {itae = 1.0}")
        bad = sorted(set(v) - set(L.METRIC_NAMES))
        if bad:
            raise ValueError(
                f"objective table has unknown metric(s) {', '.join(bad)}; allowed: "
                f"{', '.join(L.METRIC_NAMES)}"
            )
        if not any(w > 0 for w in v.values()):
            raise ValueError("objective table needs at least one weight > 0")
        return v

    @field_validator("parameters")
    @classmethod
    def _parameters(cls, v: dict[str, ParameterBounds]) -> dict[str, ParameterBounds]:
        if not v:
            raise ValueError('no parameters to tune; add e.g. "eso.omega0" = {lo=10, hi=1000}')
        unknown = sorted(set(v) - set(L.FLOAT_COLUMNS))
        if unknown:
            raise ValueError(
                f"unknown parameter name(s) {', '.join(repr(u) for u in unknown)}; allowed: "
                "the engine columns, e.g. " + ", ".join(list(L.FLOAT_COLUMNS)[:8]) + ", ..."
            )
        return v

    def with_horizon(self, scenario_t_final: float, source: str = "") -> TuneSettings:
        """These settings with ``t_final`` resolved against the scenario's horizon: the
        scenario's when not given; raises :class:`aiofl.config.ConfigError` when the given
        one is longer (the runs would score what the scenario does not describe)."""
        from aiofl.config import ConfigError

        if self.t_final is None:
            return self.model_copy(update={"t_final": float(scenario_t_final)})
        if self.t_final > scenario_t_final * (1 + 1e-12):
            raise ConfigError(
                f"invalid [tune]{' of ' + source if source else ''}: tune.t_final = "
                f"{self.t_final:g} s is longer than the scenario's horizon (scenario.t_final "
                f"= {scenario_t_final:g} s); allowed: 0 < tune.t_final <= {scenario_t_final:g}"
                " s (leave it out to tune over the scenario's horizon)"
            )
        return self

    def budget(self) -> str:
        """One-line description of the search budget."""
        return (
            f"{self.algorithm.upper()} population {self.population} x {self.generations} "
            f"generations, seed {self.seed}"
        )


def parse_tune_settings(data: Mapping[str, Any] | TuneSettings | None) -> TuneSettings:
    """Validate a ``[tune]`` table; raises :class:`aiofl.config.ConfigError` naming the field."""
    from aiofl.config import ConfigError

    if isinstance(data, TuneSettings):
        return data
    if data is None:
        raise ConfigError("[tune]: the config has no [tune] table (needed by `aiofl tune`)")
    try:
        return TuneSettings.model_validate(dict(data))
    except ValidationError as exc:
        lines = ["invalid [tune]:"]
        for err in exc.errors():
            loc = ".".join(str(p) for p in err["loc"])
            msg = err["msg"]
            if err["type"] == "extra_forbidden":
                msg = "unknown key"
            msg = msg.removeprefix("Value error, ")
            where = f"tune.{loc}" if loc else "tune"
            if isinstance(err.get("input"), dict) and err["type"] == "value_error":
                lines.append(f"  {where}: {msg}")  # a table's own check names its fields
                continue
            got = repr(err.get("input"))
            got = got if len(got) <= 100 else got[:97] + "..."
            lines.append(f"  {where}: {msg} (got {got})")
        raise ConfigError("\n".join(lines)) from None


# ---------------------------------------------------------------- search space
class SearchSpace:
    """Unit-cube encoding of the tuned parameters (linear or log per parameter)."""

    def __init__(self, parameters: Mapping[str, ParameterBounds]) -> None:
        self.names: tuple[str, ...] = tuple(parameters)
        b = [parameters[n] for n in self.names]
        self.log = np.array([p.log for p in b], dtype=bool)
        lo = np.array([p.lo for p in b], dtype=np.float64)
        hi = np.array([p.hi for p in b], dtype=np.float64)
        self.lo, self.hi = lo, hi
        with np.errstate(divide="ignore", invalid="ignore"):
            self._a = np.where(self.log, np.log(np.where(self.log, lo, 1.0)), lo)
            self._b = np.where(self.log, np.log(np.where(self.log, hi, 1.0)), hi)

    @property
    def n_var(self) -> int:
        """Number of tuned parameters."""
        return len(self.names)

    def decode(self, s: NDArray[np.float64]) -> NDArray[np.float64]:
        """Parameter values (B, d) of unit-cube points s (B, d)."""
        s = np.clip(np.asarray(s, dtype=np.float64), 0.0, 1.0)
        z = self._a + s * (self._b - self._a)
        v = z.copy()  # exp only of the log-scaled columns (a linear value overflows it)
        v[..., self.log] = np.exp(z[..., self.log])
        # land exactly on the bounds at s = 0, 1 (exp(log(x)) may differ from x in the last bit)
        v = np.where(s == 0.0, self.lo, v)
        return np.where(s == 1.0, self.hi, v)

    def encode(self, values: NDArray[np.float64]) -> NDArray[np.float64]:
        """Unit-cube points of parameter values (clipped into the bounds)."""
        v = np.clip(np.asarray(values, dtype=np.float64), self.lo, self.hi)
        z = np.where(self.log, np.log(np.where(self.log, v, 1.0)), v)
        return np.clip((z - self._a) / (self._b - self._a), 0.0, 1.0)


# ----------------------------------------------------------- structure checks
def used_parameters(controller: Controller) -> set[str]:
    """Engine columns that influence ``controller``'s closed loop (for its kinds and orders)."""
    rho, m = controller.rho, controller.n_feedback
    used = {"law.u_max", "law.u_min"}
    if controller.law == "aiofl":
        used.add("law.b0")
    if controller.eso_gains == "kalman":  # ω0 and α derived from the noise intensities
        used |= {"eso.q", "eso.r"}
    else:
        used |= {"eso.omega0", *(f"eso.alpha{i}" for i in range(1, rho + 2))}
    if controller.eso == "improved":
        used |= {"eso.k_alpha", "eso.k_beta", "eso.g_alpha", "eso.g_beta"}
    td = {"han": ["td.R"], "improved": ["td.a", "td.b", "td.c", "td.rho"], "linear": ["td.omega"]}
    used |= set(td.get(controller.td, []))
    if controller.law == "iofl" or controller.sef == "linear":
        used.add("sef.omega_c")
    elif controller.sef == "nonlinear":
        used |= {f"sef.{v}{i}" for v in ("k", "alpha", "delta") for i in range(1, m + 1)}
    else:
        used |= {f"sef.{v}{i}" for v in ("k", "kb", "mu", "alpha") for i in range(1, m + 1)}
        used.add("sef.v_limit")
    return used


# ------------------------------------------------------ writing tuned configs
_VECTOR_KEYS = {"eso": ("alpha",), "sef": ("k", "kb", "alpha", "delta", "mu")}


def _config_path(name: str) -> tuple[str, str, int | None]:
    """(table, key, index) of an engine column in the [controller] table."""
    table, key = name.split(".", 1)
    for vec in _VECTOR_KEYS.get(table, ()):
        tail = key[len(vec) :]
        if key.startswith(vec) and tail.isdigit():
            return table, vec, int(tail) - 1
    return table, key, None


def config_with_values(
    raw: Mapping[str, Any], controller: Controller, values: Mapping[str, float]
) -> dict[str, Any]:
    """A copy of the config dict ``raw`` with controller parameters set to ``values``.

    Vector entries (``sef.k2``, ``eso.alpha3``) are written into their lists, which are
    filled from ``controller``'s current values where the config left them out.

    Parameters
    ----------
    raw
        The config dict.
    controller
        Its controller.
    values
        The parameter values by engine name (``eso.omega0``, ``sef.k2``, ...).

    Returns
    -------
    dict
    """
    out = copy.deepcopy(dict(raw))
    ctrl = out.setdefault("controller", {})
    for name, val in values.items():
        table, key, idx = _config_path(name)
        sub = ctrl.setdefault(table, {})
        if idx is None:
            sub[key] = float(val)
            continue
        cur = sub.get(key)
        if not isinstance(cur, list):
            cur = []
        need = max(idx + 1, len(cur))
        if table == "eso":
            need = max(need, controller.rho + 1)
        cur = [
            float(cur[i]) if i < len(cur) else controller.value(f"{table}.{key}{i + 1}")
            for i in range(need)
        ]
        cur[idx] = float(val)
        sub[key] = cur
    return out


def _toml_key(k: str) -> str:
    return k if k.replace("_", "").replace("-", "").isalnum() and k.isascii() else repr(k)


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n") + '"'
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, Mapping):
        return "{ " + ", ".join(f"{_toml_key(k)} = {_toml_value(x)}" for k, x in v.items()) + " }"
    raise TypeError(f"cannot write {type(v).__name__} to TOML")


def to_toml(data: Mapping[str, Any], header: str = "") -> str:
    """Write a config dict as TOML (tables as ``[a.b]`` sections; floats round-trip exactly).

    Leaf tables of ``[tune.parameters]`` (``{lo, hi, log}``) are written inline.
    """
    lines = [f"# {h}" if h else "#" for h in header.splitlines()] if header else []

    def emit(table: Mapping[str, Any], path: list[str]) -> None:
        scalars = [
            (k, v) for k, v in table.items() if not isinstance(v, Mapping) or _inline(path, k)
        ]
        subs = [(k, v) for k, v in table.items() if isinstance(v, Mapping) and not _inline(path, k)]
        if path and (scalars or not subs):
            lines.append("")
            lines.append("[" + ".".join(_toml_key(p) for p in path) + "]")
        for k, v in scalars:
            lines.append(f"{_toml_key(k)} = {_toml_value(v)}")
        for k, v in subs:
            emit(v, [*path, k])

    def _inline(path: list[str], key: str) -> bool:
        return (
            (len(path) >= 2 and path[-2:] == ["tune", "parameters"])
            or (path == ["tune"] and key == "objective")
            or (path == ["scenario"] and key in ("plant_scale", "plant_overrides"))
        )

    emit(data, [])
    return "\n".join(lines).lstrip("\n") + "\n"


def update_toml(
    source: str, config: Mapping[str, Any], names: Iterable[str], header: str = ""
) -> str:
    """``source`` (a config's TOML text) with the tuned parameters set, comments and layout kept.

    Edited with tomlkit: only the entries of the tuned engine columns ``names`` (e.g.
    ``eso.omega0``, ``sef.k2``: the whole ``[controller.sef] k`` list, element by element
    where it has the same length) and the top-level ``plant`` are set, to their values in
    ``config`` (the tuned config dict, see :func:`config_with_values`); a missing table is
    added.  ``header`` lines are prepended as comments.  Parsing the result gives ``config``
    wherever ``source`` and ``config`` agree outside those entries.

    Parameters
    ----------
    source
        The config's TOML text.
    config
        The tuned config dict.
    names
        The tuned engine columns (``eso.omega0``, ``sef.k2``, ...).
    header
        Comment lines to prepend.

    Returns
    -------
    str
    """
    import tomlkit
    from tomlkit.items import Array

    doc = tomlkit.parse(source)
    ctrl_new = config.get("controller", {})
    done: set[tuple[str, str]] = set()
    for name in names:
        table, key, _ = _config_path(name)
        if (table, key) in done:
            continue
        done.add((table, key))
        value = ctrl_new[table][key]
        if "controller" not in doc:
            doc["controller"] = tomlkit.table()
        ctrl = doc["controller"]
        if table not in ctrl:
            new = tomlkit.table()
            new.add(tomlkit.nl())
            ctrl[table] = new  # type: ignore[index]
        sub = ctrl[table]  # type: ignore[index]
        cur = sub.get(key)  # type: ignore[union-attr]
        if isinstance(value, list) and isinstance(cur, Array) and len(cur) == len(value):
            for i, v in enumerate(value):
                if cur[i] != v or type(cur[i]) is not type(v):
                    cur[i] = v
        else:
            sub[key] = value  # type: ignore[index]
    if "plant" in config and doc.get("plant") != config["plant"]:
        doc["plant"] = config["plant"]
    text = tomlkit.dumps(doc)
    if header:
        lines = [f"# {h}" if h else "#" for h in header.splitlines()]
        text = "\n".join(lines) + "\n\n" + text
    return text
