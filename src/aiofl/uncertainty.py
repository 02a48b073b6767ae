r"""Model uncertainty as data: the ``[uncertainty]`` table, its draws and their aggregates.

.. code-block:: toml

    [uncertainty]
    draws = 1000                       # 1 .. MAX_DRAWS
    seed = 0
    ts = [5e-4, 2e-3]                  # optional, needs [controller.discrete]
    noise_variance = [0.0, 1e-4]       # optional, output-noise variance range
    output_delay = [0.0, 2e-3]         # optional, measurement delay range [s]
    input_delay = [0.0, 1e-3]          # optional, input (computation) delay range [s]
    [uncertainty.parameters]           # true-plant parameters, as factors on the nominal
    J_l = { uniform = 0.2 }            # factor ~ U[1 - p, 1 + p], 0 < p < 1
    K_s = { normal = 0.05 }            # factor = 1 + sigma z, z ~ N(0, 1), |z| < 1/sigma
    R_m = { log_uniform = [0.5, 2.0] } # ln factor ~ U[ln a, ln b], 0 < a < b
    rig_lag = { uniform = 0.5 }        # a rig's parameters too (aiofl.plants.actuated)

**Common random numbers.**  The draws depend only on ``(seed, the table, draws)`` (and, for
``ts``, the engine step ``dt`` that sample times are rounded to), never on the controller:
every design is scored on the same plants, so two designs' results are paired.  Each drawn
quantity has its own stream, ``numpy.random.Generator(PCG64(SeedSequence(seed,
spawn_key=(crc32(name),))))``: adding or removing a parameter does not change the other
parameters' draws, and every value is a fixed transform of one uniform variate
:math:`u_k \in [0, 1)` (inverse CDF), so the first ``n`` of ``N`` draws are the ``n``
draws of a run with ``draws = n`` (prefix-stable).

**How a draw reaches the engine** (:meth:`Draws.scenarios`): the factors multiply the true
plant's parameters from t = 0 (``Scenario.plant_scale`` with ``parameter_change_time =
0``); the controller's nominal model is unchanged.  They compose with a scenario's own
change at t = 0 by multiplication (the shipped S2 presets' J_l × 1.4 becomes J_l × 1.4 ×
f).  A scenario whose own plant change is at t > 0 is refused for now: the engine's scenario
carries a single parameter change, so a draw cannot both apply from t = 0 and be
compounded at the change time.  A drawn noise variance replaces the scenario's (the
sensor's, :mod:`aiofl.sensor`); a drawn sample time replaces ``[controller.discrete] ts``
(:meth:`Draws.samplings`), the sensor's quantum kept.  Drawn transport delays replace the
scenario's ``output_delay`` / ``input_delay`` (a ``[rig]``'s): uniform over the integer
multiples of the step dt in the range (the sampled engine holds exactly those,
:func:`aiofl.engine.discrete_rows.delay_steps`), like ``ts``.  A rig's actuator and friction
are plant parameters (``rig_lag``, ``rig_coulomb``, ...; :mod:`aiofl.plants.actuated`),
drawn as factors like any other.

**Every draw has its own noise realisation.**  When the measurement is noisy (the
scenario's or the drawn variance > 0), draw k's noise seed is
:func:`aiofl.scenario.realisation_seed` (scenario noise seed, 1 + n_k), with n_k the k-th
integer of the stream named ``"noise_seed"`` of the table's seed: deterministic (same
seed, same noise), prefix-stable, and different between draws, so a design is never judged
on one noise sequence shared by all draws.

**Aggregates** over the draws (:func:`aggregate`) treat a diverged draw as :math:`+\infty`:
``mean`` and ``worst`` are then infinite (the design is infeasible), and ``cvar`` is the
Conditional Value-at-Risk at level α (Rockafellar & Uryasev, *Optimization of conditional
value-at-risk*, J. Risk 2(3), 2000): the mean of the worst :math:`\lceil (1-\alpha) K\rceil`
of K values.
"""

from __future__ import annotations

import math
import zlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Annotated, Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray
from pydantic import Field, field_validator, model_validator

from aiofl.scenario import DELAY_MAX, Scenario, realisation_seed
from aiofl.table_model import TableModel
from aiofl.text import normal_keys

__all__ = [
    "ABSOLUTE",
    "AGGREGATES",
    "MAX_DRAWS",
    "MAX_FULL_FACTORIAL",
    "Distribution",
    "Draws",
    "UncertaintyModel",
    "aggregate",
    "box_bounds",
    "box_draws",
    "corner_design",
    "corner_draws",
    "cvar",
    "sample_draws",
]

#: most draws of one ``[uncertainty]`` table (one engine member each)
MAX_DRAWS = 100_000
#: the names :func:`aggregate` accepts
AGGREGATES = ("mean", "worst", "cvar")
#: drawn quantities that are values, not factors on a nominal parameter
ABSOLUTE = ("ts", "noise_variance", "output_delay", "input_delay")
#: drawn transport delays (scenario fields), multiples of dt in [0, DELAY_MAX]
DELAYS = ("output_delay", "input_delay")


PosFinite = Annotated[float, Field(gt=0, allow_inf_nan=False)]


class Distribution(TableModel):
    r"""One parameter's distribution, as a factor :math:`f` on its nominal value.

    Exactly one of:

    ``uniform = p``
        :math:`f = 1 + p(2u - 1)`, i.e. :math:`f \sim U[1-p, 1+p]`, :math:`0 < p < 1`.
    ``normal = σ``
        :math:`f = 1 + \sigma z`, :math:`z` standard normal truncated to
        :math:`|z| < 1/\sigma` (so :math:`0 < f < 2` and :math:`E f = 1`), drawn by the
        inverse CDF of ``scipy.stats.truncnorm``; :math:`0 < \sigma \le 0.5`.
    ``log_uniform = [a, b]``
        :math:`\ln f \sim U[\ln a, \ln b]`, :math:`0 < a < b`.
    """

    uniform: Annotated[float, Field(gt=0, lt=1)] | None = None
    normal: Annotated[float, Field(gt=0, le=0.5)] | None = None
    log_uniform: Annotated[list[PosFinite], Field(min_length=2, max_length=2)] | None = None

    @model_validator(mode="after")
    def _one(self) -> Distribution:
        given = [k for k in ("uniform", "normal", "log_uniform") if getattr(self, k) is not None]
        if len(given) != 1:
            raise ValueError(
                f"a parameter's distribution sets exactly one of uniform = p, normal = sigma, "
                f"log_uniform = [a, b]; got {', '.join(given) or 'none'}"
            )
        if self.log_uniform is not None and not self.log_uniform[0] < self.log_uniform[1]:
            raise ValueError(
                f"log_uniform = {self.log_uniform}; allowed: [a, b] with 0 < a < b (factors)"
            )
        return self

    @property
    def kind(self) -> str:
        """``"uniform"``, ``"normal"`` or ``"log_uniform"``."""
        return next(k for k in ("uniform", "normal", "log_uniform") if getattr(self, k) is not None)

    def factors(self, u: NDArray[np.float64]) -> NDArray[np.float64]:
        """The factors for uniform variates ``u`` in [0, 1) (inverse CDF)."""
        if self.uniform is not None:
            return 1.0 + self.uniform * (2.0 * u - 1.0)
        if self.normal is not None:
            from scipy.stats import truncnorm

            bound = 1.0 / self.normal
            z = truncnorm.ppf(u, -bound, bound)
            return np.clip(1.0 + self.normal * z, np.nextafter(0.0, 1.0), None)
        a, b = self.log_uniform  # type: ignore[misc]
        return np.exp(math.log(a) + u * (math.log(b) - math.log(a)))

    def bounds(self) -> tuple[float, float]:
        r"""The box edge of this factor: ``uniform`` :math:`[1-p, 1+p]`, ``log_uniform``
        :math:`[a, b]` (the support), ``normal`` :math:`1 \pm 3\sigma` (99.7 % of the
        untruncated law) clipped to :math:`[0.01, 1.99]` (the truncated support is (0, 2))."""
        if self.uniform is not None:
            return 1.0 - self.uniform, 1.0 + self.uniform
        if self.normal is not None:
            half = min(3.0 * self.normal, 0.99)
            return 1.0 - half, 1.0 + half
        a, b = self.log_uniform  # type: ignore[misc]
        return float(a), float(b)


#: a range [a, b] of non-negative numbers
Pair = Annotated[
    list[Annotated[float, Field(ge=0, allow_inf_nan=False)]], Field(min_length=2, max_length=2)
]


class UncertaintyModel(TableModel):
    """The ``[uncertainty]`` table (see the module docstring)."""

    draws: Annotated[int, Field(ge=1, le=MAX_DRAWS)] = 64
    seed: Annotated[int, Field(ge=0, lt=2**63)] = 0
    parameters: dict[str, Distribution] = Field(default_factory=dict)
    ts: Pair | None = None
    noise_variance: Pair | None = None
    output_delay: Pair | None = None
    input_delay: Pair | None = None

    @field_validator("parameters")
    @classmethod
    def _parameter_names(cls, v: dict[str, Distribution]) -> dict[str, Distribution]:
        # plant parameter names, read as the plant declares them (Unicode NFKC)
        return normal_keys("uncertainty.parameters", v)

    @model_validator(mode="after")
    def _ranges(self) -> UncertaintyModel:
        for key in ("ts", "noise_variance", *DELAYS):
            pair = getattr(self, key)
            if pair is not None and not pair[0] <= pair[1]:
                raise ValueError(f"uncertainty.{key} = {pair}; allowed: [a, b] with a <= b")
        if self.ts is not None and not (self.ts[0] > 0 and self.ts[1] <= 1.0):
            raise ValueError(f"uncertainty.ts = {self.ts}; allowed: [a, b] with 0 < a <= b <= 1 s")
        for key in DELAYS:
            pair = getattr(self, key)
            if pair is not None and pair[1] > DELAY_MAX:
                raise ValueError(
                    f"uncertainty.{key} = {pair}; allowed: [a, b] with 0 <= a <= b <= "
                    f"{DELAY_MAX:g} s"
                )
        if not self.parameters and all(getattr(self, k) is None for k in ABSOLUTE):
            raise ValueError(
                "nothing is uncertain; set [uncertainty.parameters] (e.g. "
                "J_l = { uniform = 0.2 }), ts, noise_variance, output_delay or input_delay "
                "= [a, b]"
            )
        return self

    def check(self, param_names: Sequence[str], *, discrete: bool, dt: float) -> None:
        """Refuse parameters the plant does not have, and ``ts`` without a sampled
        controller or without a multiple of ``dt`` in range; raises ``ValueError``.

        Parameters
        ----------
        param_names, discrete, dt
            The plant's parameter names, whether the controller is sampled, the step [s].
        """
        unknown = sorted(set(self.parameters) - set(param_names))
        if unknown:
            raise ValueError(
                f"uncertainty.parameters: unknown plant parameter(s) {', '.join(unknown)}; "
                f"allowed: {', '.join(param_names)}"
            )
        if self.ts is not None:
            if not discrete:
                raise ValueError(
                    "uncertainty.ts is set but the config has no [controller.discrete] table; "
                    "a sample-time range needs a sampled controller (add [controller.discrete] "
                    "ts = ...) or remove uncertainty.ts"
                )
            _ts_steps(self.ts, dt)
        for key in DELAYS:
            if getattr(self, key) is not None:
                _delay_steps(key, getattr(self, key), dt)


def _delay_steps(key: str, pair: Sequence[float], dt: float) -> tuple[int, int]:
    """The integer k >= 0 with ``pair[0] <= k dt <= pair[1]`` (within 1e-9), as (lo, hi)."""
    lo = max(math.ceil(pair[0] / dt - 1e-9), 0)
    hi = math.floor(pair[1] / dt + 1e-9)
    if hi < lo:
        raise ValueError(
            f"uncertainty.{key} = {list(pair)} holds no integer multiple of simulation.dt = "
            f"{dt:g} s; allowed: a range containing k*dt for some integer k >= 0"
        )
    return lo, hi


def _ts_steps(ts: Sequence[float], dt: float) -> tuple[int, int]:
    """The integer multiples k of ``dt`` with ``ts[0] <= k dt <= ts[1]`` (within 1e-9)."""
    lo = math.ceil(ts[0] / dt - 1e-9)
    hi = math.floor(ts[1] / dt + 1e-9)
    if lo < 1 or hi < lo:
        raise ValueError(
            f"uncertainty.ts = {list(ts)} holds no integer multiple of simulation.dt = {dt:g} s; "
            "allowed: a range containing k*dt for some integer k >= 1"
        )
    return lo, hi


def _uniforms(seed: int, name: str, n: int) -> NDArray[np.float64]:
    """``n`` variates U[0, 1) of the stream named ``name`` (independent of other names)."""
    ss = np.random.SeedSequence(seed, spawn_key=(zlib.crc32(name.encode()),))
    return np.random.Generator(np.random.PCG64(ss)).random(n)


@dataclass(frozen=True)
class Draws:
    """K draws of an ``[uncertainty]`` table.

    Attributes
    ----------
    seed
        The seed they were drawn with.
    factors
        Per plant parameter (sorted by name), the (K,) factors on its nominal value.
    ts
        (K,) sample times [s] (integer multiples of dt), or None.
    noise_variance
        (K,) output-noise variances, or None.
    noise_seeds
        (K,) integers that seed each draw's noise realisation (module docstring), or None:
        every draw keeps the scenario's noise seed.
    output_delay, input_delay
        (K,) transport delays [s] (integer multiples of dt), or None.
    """

    seed: int
    factors: Mapping[str, NDArray[np.float64]]
    ts: NDArray[np.float64] | None = None
    noise_variance: NDArray[np.float64] | None = None
    noise_seeds: NDArray[np.int64] | None = None
    output_delay: NDArray[np.float64] | None = None
    input_delay: NDArray[np.float64] | None = None

    def noise_seed(self, base: Scenario, k: int) -> int:
        """The noise seed of draw ``k`` on scenario ``base`` (its own seed without
        :attr:`noise_seeds`)."""
        if self.noise_seeds is None:
            return base.noise_seed
        return realisation_seed(base.noise_seed, 1 + int(self.noise_seeds[k]))

    def subset(self, idx: slice) -> Draws:
        """The draws ``idx`` (every drawn quantity sliced alike)."""

        def cut(a: NDArray[Any] | None) -> NDArray[Any] | None:
            return None if a is None else a[idx]

        return Draws(
            seed=self.seed,
            factors={k: v[idx] for k, v in self.factors.items()},
            ts=cut(self.ts),
            noise_variance=cut(self.noise_variance),
            noise_seeds=cut(self.noise_seeds),
            output_delay=cut(self.output_delay),
            input_delay=cut(self.input_delay),
        )

    def concat(self, other: Draws) -> Draws:
        """These draws followed by ``other`` (the same quantities drawn; the seed is
        this one's).  Raises ``ValueError`` when the drawn quantities differ."""
        if set(self.factors) != set(other.factors) or any(
            (getattr(self, a) is None) != (getattr(other, a) is None)
            for a in ("ts", "noise_variance", "noise_seeds", *DELAYS)
        ):
            raise ValueError("Draws.concat: the two sets draw different quantities")

        def cat(a: NDArray[Any] | None, b: NDArray[Any] | None) -> NDArray[Any] | None:
            return None if a is None or b is None else np.concatenate([a, b])

        return Draws(
            seed=self.seed,
            factors={k: np.concatenate([v, other.factors[k]]) for k, v in self.factors.items()},
            ts=cat(self.ts, other.ts),
            noise_variance=cat(self.noise_variance, other.noise_variance),
            noise_seeds=cat(self.noise_seeds, other.noise_seeds),
            output_delay=cat(self.output_delay, other.output_delay),
            input_delay=cat(self.input_delay, other.input_delay),
        )

    def __len__(self) -> int:
        for arr in (
            *self.factors.values(),
            self.ts,
            self.noise_variance,
            self.output_delay,
            self.input_delay,
        ):
            if arr is not None:
                return len(arr)
        return 0

    def columns(self) -> dict[str, NDArray[np.float64]]:
        """Every drawn quantity by name (parameters as factors, then ``ts``,
        ``noise_variance``, ``output_delay``, ``input_delay``)."""
        cols = dict(self.factors)
        for key in ABSOLUTE:
            if getattr(self, key) is not None:
                cols[key] = getattr(self, key)
        return cols

    def scenarios(self, base: Scenario) -> list[Scenario]:
        """One scenario per draw: ``base`` with the drawn plant from t = 0 (and the drawn
        noise variance); raises ``ValueError`` for a base with its own plant change at t > 0
        (see the module docstring)."""
        has_change = bool(base.plant_scale or base.plant_overrides)
        if self.factors and has_change and base.parameter_change_time > 0:
            raise ValueError(
                f"scenario {base.name!r} changes the plant at t = {base.parameter_change_time:g} "
                "s; uncertain plant parameters apply from t = 0 and the engine's scenario holds "
                "one parameter change, so they cannot be combined yet (use a scenario without "
                "plant_scale / plant_overrides, or parameter_change_time = 0)"
            )
        out = []
        for k in range(len(self)):
            scale = dict(base.plant_scale)
            for name, f in self.factors.items():
                scale[name] = scale.get(name, 1.0) * float(f[k])
            changes: dict[str, Any] = {}
            if self.factors:
                changes.update(plant_scale=scale, parameter_change_time=0.0)
            if self.noise_variance is not None:
                changes["noise_variance"] = float(self.noise_variance[k])
            for key in DELAYS:
                if getattr(self, key) is not None:
                    changes[key] = float(getattr(self, key)[k])
            if changes.get("noise_variance", base.noise_variance) > 0:
                changes["noise_seed"] = self.noise_seed(base, k)  # its own realisation
            out.append(replace(base, **changes) if changes else base)
        return out

    def samplings(self, base: Any) -> list[Any]:
        """One sampling setting per draw: ``base`` (an ``aiofl.engine.discrete_rows.Sampling``,
        or None) with the drawn sample time; ``[base] * K`` if ``ts`` is not drawn."""
        if self.ts is None or base is None:
            return [base] * len(self)
        return [replace(base, ts=float(t)) for t in self.ts]


def sample_draws(
    spec: UncertaintyModel, *, draws: int | None = None, seed: int | None = None, dt: float = 1e-4
) -> Draws:
    """Draw the table's uncertain quantities (common random numbers, see the module
    docstring).  ``draws`` / ``seed`` override the table's; ``dt`` is the engine step the
    sample times are multiples of.

    Parameters
    ----------
    spec
        The ``[uncertainty]`` model.
    draws, seed
        The number of draws (1..:data:`MAX_DRAWS`) and the seed (None: the table's).
    dt
        The engine step [s] the drawn sample times are multiples of.

    Returns
    -------
    Draws
    """
    n = spec.draws if draws is None else int(draws)
    s = spec.seed if seed is None else int(seed)
    if not 1 <= n <= MAX_DRAWS:
        raise ValueError(f"uncertainty.draws = {n}; allowed: 1 <= draws <= {MAX_DRAWS}")
    if not 0 <= s < 2**63:
        raise ValueError(f"uncertainty.seed = {s}; allowed: 0 <= seed < 2**63")
    factors = {
        name: spec.parameters[name].factors(_uniforms(s, name, n))
        for name in sorted(spec.parameters)
    }
    ts = None
    if spec.ts is not None:
        lo, hi = _ts_steps(spec.ts, dt)
        k = lo + np.minimum(np.floor(_uniforms(s, "ts", n) * (hi - lo + 1)), hi - lo)
        ts = k * dt
    nv = None
    if spec.noise_variance is not None:
        a, b = spec.noise_variance
        nv = a + (b - a) * _uniforms(s, "noise_variance", n)
    delays = {}
    for key in DELAYS:
        if getattr(spec, key) is not None:
            lo, hi = _delay_steps(key, getattr(spec, key), dt)
            k = lo + np.minimum(np.floor(_uniforms(s, key, n) * (hi - lo + 1)), hi - lo)
            delays[key] = k * dt
    ns = np.random.Generator(
        np.random.PCG64(np.random.SeedSequence(s, spawn_key=(zlib.crc32(b"noise_seed"),)))
    ).integers(0, 2**62, n, dtype=np.int64)
    return Draws(seed=s, factors=factors, ts=ts, noise_variance=nv, noise_seeds=ns, **delays)


# ------------------------------------------------------------------ the box and its corners
#: a box of at most this many dimensions is checked at all its 2^k corners
MAX_FULL_FACTORIAL = 12


def box_bounds(spec: UncertaintyModel, *, dt: float = 1e-4) -> dict[str, tuple[float, float]]:
    """The uncertainty box: per drawn quantity (parameters sorted by name, then ``ts``,
    ``noise_variance``) its ``(low, high)`` edge (:meth:`Distribution.bounds`; ``ts``: the
    smallest and largest multiple of ``dt`` in range)."""
    out = {name: spec.parameters[name].bounds() for name in sorted(spec.parameters)}
    if spec.ts is not None:
        lo, hi = _ts_steps(spec.ts, dt)
        out["ts"] = (lo * dt, hi * dt)
    if spec.noise_variance is not None:
        out["noise_variance"] = (float(spec.noise_variance[0]), float(spec.noise_variance[1]))
    for key in DELAYS:
        if getattr(spec, key) is not None:
            lo, hi = _delay_steps(key, getattr(spec, key), dt)
            out[key] = (lo * dt, hi * dt)
    return out


def _generators(n: int) -> list[tuple[int, ...]]:
    """The first ``n`` subsets of odd size >= 3 of the 12 base factors (by size, then
    lexicographically): the generators of the extra factors of a fractional factorial."""
    import itertools

    out: list[tuple[int, ...]] = []
    for size in range(3, MAX_FULL_FACTORIAL + 1, 2):
        for combo in itertools.combinations(range(MAX_FULL_FACTORIAL), size):
            out.append(combo)
            if len(out) == n:
                return out
    raise ValueError(
        f"a box of {MAX_FULL_FACTORIAL + n} dimensions; allowed: at most "
        f"{MAX_FULL_FACTORIAL + len(out)} (the resolution-IV corner design runs out of generators)"
    )


def corner_design(k: int) -> tuple[NDArray[np.int8], str]:
    r"""The corners checked of a k-dimensional box, as a (N, k) table of signs ±1.

    :math:`k \le` :data:`MAX_FULL_FACTORIAL`: the full factorial, all :math:`N = 2^k`
    corners (row i, column j: +1 when bit j of i is set).  Larger k: a two-level
    :math:`2^{k-p}` fractional factorial with :math:`N = 2^{12}` runs (Box, Hunter &
    Hunter, *Statistics for Experimenters*, 2nd ed., 2005, ch. 6): the first 12 factors
    full factorial, factor 12 + m the product of the base factors of generator m, the
    odd-sized subsets of size >= 3 in order.  Every word of the defining relation then has
    even length >= 4, so the design has resolution IV (no main effect aliased with another
    main effect or a two-factor interaction).  Returns the table and a one-line description.
    """
    if k < 1:
        raise ValueError("a corner design needs at least one dimension")
    n_base = min(k, MAX_FULL_FACTORIAL)
    rows = np.arange(2**n_base)[:, None]
    base = np.where((rows >> np.arange(n_base)) & 1, 1, -1).astype(np.int8)
    if k <= MAX_FULL_FACTORIAL:
        return base, f"full factorial: all 2^{k} = {2**k} corners"
    extra = [np.prod(base[:, list(g)], axis=1) for g in _generators(k - n_base)]
    table = np.column_stack([base, *extra]).astype(np.int8)
    return table, (
        f"2^({k}-{k - n_base}) fractional factorial of resolution IV: {2**n_base} of the "
        f"2^{k} corners (first {n_base} factors full, the others products of odd-sized "
        "generator sets)"
    )


def _box_values(
    box: Mapping[str, tuple[float, float]], unit: NDArray[np.float64], dt: float, seed: int
) -> Draws:
    """Draws at the points ``unit`` (N, k) of the unit cube mapped onto ``box`` (``ts``
    rounded to a multiple of ``dt``); noise seeds from the stream ``"box_noise_seed"``."""
    names = list(box)
    cols = {}
    for j, name in enumerate(names):
        lo, hi = box[name]
        cols[name] = lo + np.clip(unit[:, j], 0.0, 1.0) * (hi - lo)
    ts = cols.pop("ts", None)
    if ts is not None:
        ts = np.round(ts / dt) * dt
    nv = cols.pop("noise_variance", None)
    delays = {k: np.round(cols.pop(k) / dt) * dt for k in DELAYS if k in cols}
    ns = np.random.Generator(
        np.random.PCG64(np.random.SeedSequence(seed, spawn_key=(zlib.crc32(b"box_noise_seed"),)))
    ).integers(0, 2**62, len(unit), dtype=np.int64)
    return Draws(seed=seed, factors=cols, ts=ts, noise_variance=nv, noise_seeds=ns, **delays)


def corner_draws(spec: UncertaintyModel, *, dt: float = 1e-4) -> tuple[Draws, str]:
    """The corners of the box of ``spec`` (:func:`box_bounds`, :func:`corner_design`) as
    :class:`Draws` (one per corner, in the design's row order), and the design's
    description.  Deterministic: the same table gives the same corners (their noise seeds,
    used only with a noisy measurement, come from the table's seed)."""
    box = box_bounds(spec, dt=dt)
    signs, text = corner_design(len(box))
    return _box_values(box, (signs + 1.0) / 2.0, dt, spec.seed), text


def box_draws(spec: UncertaintyModel, unit: ArrayLike, *, dt: float = 1e-4) -> Draws:
    """Draws at points of the box of ``spec`` given in unit coordinates: ``unit`` (N, k),
    column j in [0, 1] from the low to the high edge of :func:`box_bounds`'s j-th entry.

    Parameters
    ----------
    spec, unit, dt
        The ``[uncertainty]`` model, the points (N, k) and the engine step [s].

    Returns
    -------
    Draws
    """
    u = np.atleast_2d(np.asarray(unit, dtype=np.float64))
    box = box_bounds(spec, dt=dt)
    if u.shape[1] != len(box):
        raise ValueError(f"box points have {u.shape[1]} columns; the box has {len(box)}")
    return _box_values(box, u, dt, spec.seed)


# ------------------------------------------------------------------ aggregates
def cvar(values: ArrayLike, alpha: float = 0.9, axis: int = -1) -> NDArray[np.float64]:
    r"""CVaR\ :sub:`α` along ``axis``: the mean of the worst :math:`m = \lceil (1-\alpha) K
    \rceil` of K values (Rockafellar & Uryasev 2000, the upper-tail mean for a loss).

    ``(1 - α) K`` is rounded up after removing a 1e-9 floating-point excess, so
    :math:`\alpha = 0.7, K = 10` gives m = 3, not 4.  A +inf value (a diverged draw) among
    the worst m makes the result +inf.

    Parameters
    ----------
    values, alpha, axis
        The values (losses); the level, 0 ≤ α < 1 (0.9: the worst 10 %); their axis.

    Returns
    -------
    ndarray
    """
    if not 0.0 <= alpha < 1.0:
        raise ValueError(f"cvar alpha = {alpha}; allowed: 0 <= alpha < 1")
    x = np.moveaxis(np.asarray(values, dtype=np.float64), axis, -1)
    k = x.shape[-1]
    m = max(1, math.ceil((1.0 - alpha) * k - 1e-9))
    worst = np.sort(x, axis=-1)[..., k - m :]
    return np.mean(worst, axis=-1)


def aggregate(
    values: ArrayLike,
    how: Literal["mean", "worst", "cvar"] = "mean",
    *,
    alpha: float = 0.9,
    failed: ArrayLike | None = None,
    axis: int = -1,
) -> NDArray[np.float64]:
    r"""Aggregate a metric over draws (along ``axis``), diverged draws as :math:`+\infty`.

    ``mean``: :math:`\frac1K\sum_k v_k`; ``worst``: :math:`\max_k v_k`; ``cvar``:
    :func:`cvar` at level ``alpha``.  ``diverged`` (same shape, bool) marks draws whose
    value is replaced by +inf; a NaN value is treated as diverged too.  A +inf result means
    the design is infeasible.

    Parameters
    ----------
    values
        The metric's values.
    how
        ``"mean"``, ``"worst"`` or ``"cvar"``.
    alpha
        The CVaR level.
    failed
        Diverged draws, bool, the shape of ``values`` (the ``diverged`` above); None: none.
    axis
        The axis of the draws.

    Returns
    -------
    ndarray
    """
    x = np.array(values, dtype=np.float64)
    if failed is not None:
        x[np.asarray(failed, dtype=bool)] = np.inf
    x[np.isnan(x)] = np.inf
    if x.shape[axis] == 0:
        raise ValueError("aggregate over zero draws")
    if how == "mean":
        return np.mean(x, axis=axis)
    if how == "worst":
        return np.max(x, axis=axis)
    if how == "cvar":
        return cvar(x, alpha, axis)
    raise ValueError(f"aggregate = {how!r}; allowed: {', '.join(AGGREGATES)}")
