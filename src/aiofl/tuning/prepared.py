r"""Preparing a tuning run: everything is validated before anything is run or written.

:func:`prepare` checks a config and its ``[tune]`` settings and returns the run's
definition (:class:`Prepared`): the search space (:class:`aiofl.tuning.space.SearchSpace`),
the evaluation spec of one batched engine call (:class:`aiofl.tuning.evaluate.EvalSpec`,
with the robust draws of :func:`draw_fields`), the objective
(:class:`aiofl.tuning.objective.Objective`), the initial population and the fingerprint a
checkpoint is checked against.  ``aiofl tune`` prepares once (bad input: exit status 2
before anything runs) and hands the result to :func:`aiofl.tuning.search.tune`, which
searches it as a :class:`aiofl.tuning.problem.TuningProblem`.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from aiofl.tuning.ceiling import clip_to_ceiling
from aiofl.tuning.checkpoint import CHECKPOINT_FORMAT
from aiofl.tuning.objective import Objective
from aiofl.tuning.space import (
    MAX_POPULATION,
    SearchSpace,
    TuneSettings,
    config_with_values,
    parse_tune_settings,
    used_parameters,
)

if TYPE_CHECKING:  # pragma: no cover
    from aiofl.config import RunConfig
    from aiofl.tuning.evaluate import EvalSpec

__all__ = ["Prepared", "draw_fields", "prepare"]


# ---------------------------------------------------------------------- preparing
@dataclass(frozen=True)
class Prepared:
    """A validated tuning run, before anything is run (:func:`prepare`).

    Attributes
    ----------
    config
        The config (its ``[tune]`` table is not part of :attr:`spec`).
    settings
        The ``[tune]`` settings with the overrides, the horizon and the ω0 ceiling applied.
    space
        The search space (unit cube to parameter values).
    spec
        What the evaluator simulates (plain data, picklable).
    objective
        What the run minimises, and its scores.
    initial
        The initial population in the unit cube.
    fingerprint
        The run's identity (a checkpoint of another run is refused).
    source
        Where the config came from (file or preset name).
    notes
        What preparing changed (``tune.omega0_ceiling``).
    """

    config: RunConfig
    settings: TuneSettings
    space: SearchSpace
    spec: EvalSpec
    objective: Objective
    initial: NDArray[np.float64]
    fingerprint: str
    source: str
    notes: tuple[str, ...] = ()


def _check_parameters(cfg: RunConfig, settings: TuneSettings) -> None:
    from aiofl.config import ConfigError, parse_config

    used = used_parameters(cfg.controller)
    c = cfg.controller
    for name, b in settings.parameters.items():
        if name not in used:
            raise ConfigError(
                f"tune.parameters.{name!r}: has no effect on this controller (structure "
                f"{c.structure}: eso={c.eso!r}, td={c.td!r}, sef={c.sef!r}, law={c.law!r}, "
                f"rho={c.rho}, n_feedback={c.n_feedback}); allowed: {', '.join(sorted(used))}"
            )
        for which, val in (("lo", b.lo), ("hi", b.hi)):
            try:
                parse_config(config_with_values(cfg.raw, c, {name: val}), "tune bounds")
            except ConfigError as exc:
                detail = str(exc).split("\n", 1)[-1].strip()
                raise ConfigError(
                    f"tune.parameters.{name!r}.{which} = {val}: outside the range the config "
                    f"allows for this parameter: {detail}"
                ) from None


def _initial_population(space: SearchSpace, cfg: RunConfig, settings: TuneSettings) -> Any:
    from scipy.stats import qmc

    rng = np.random.default_rng([settings.seed, 0x5EED])
    pop = qmc.LatinHypercube(d=space.n_var, rng=rng).random(settings.population)
    if settings.include_initial:
        current = np.array([cfg.controller.value(n) for n in space.names])
        pop[0] = space.encode(current[None, :])[0]
    return pop


def prepare(
    run_config: RunConfig | str | Path,
    settings: TuneSettings | Mapping[str, Any] | None = None,
    *,
    draws: Sequence[Mapping[str, Any]] | None = None,
    **overrides: Any,
) -> Prepared:
    """Validate a config and its tune settings before anything is run or written.

    Parameters
    ----------
    run_config
        A :class:`~aiofl.config.RunConfig`, a TOML path or a preset name.
    settings
        The ``[tune]`` settings; default: the config's ``[tune]`` table.
    draws
        Robust runs only: the K scenario changes explicitly (dicts of
        :class:`~aiofl.scenario.Scenario` fields, e.g. ``{"plant_scale": {"J_l": 1.2}}``)
        instead of drawing them from the config's ``[uncertainty]`` table.
    **overrides
        Settings fields to replace (e.g. ``seed=3``; None: not replaced).

    Returns
    -------
    Prepared

    Raises
    ------
    aiofl.config.ConfigError
        On bad input, naming the field.
    """
    from aiofl.config import ConfigError, load_config
    from aiofl.limits import check_run_size
    from aiofl.tuning.evaluate import EvalSpec

    cfg = load_config(run_config) if isinstance(run_config, (str, Path)) else run_config
    source = str(run_config) if cfg is not run_config else cfg.name
    st = parse_tune_settings(settings if settings is not None else cfg.raw.get("tune"))
    overrides = {k: v for k, v in overrides.items() if v is not None}
    st = parse_tune_settings({**st.model_dump(exclude_none=True), **overrides})
    st = st.with_horizon(cfg.scenario.t_final, source)  # t_final: the scenario's by default
    st, notes = clip_to_ceiling(cfg, st, source)  # tune.omega0_ceiling: eso.omega0's hi
    _check_parameters(cfg, st)
    try:  # the tuning horizon's size, before any member is allocated
        check_run_size(
            st.t_final, st.dt or cfg.dt, noise_hold=cfg.scenario.noise_hold, what="[tune]"
        )
    except ValueError as exc:
        msg = str(exc).replace("scenario.t_final", "tune.t_final")
        if st.dt is not None:
            msg = msg.replace("simulation.dt", "tune.dt")
        raise ConfigError(f"invalid [tune] of {source or cfg.name}: {msg}") from None
    if st.dt:  # a sampled controller's Ts must be a multiple of the tuning step too
        replace(cfg, dt=st.dt).check_sampling()
    space = SearchSpace(st.parameters)
    raw = {k: v for k, v in cfg.raw.items() if k != "tune"}
    robust_draws = _robust_draws(cfg, st, draws, source)
    spec = EvalSpec(
        config=raw,
        names=space.names,
        t_final=st.t_final,
        dt=st.dt or cfg.dt,
        method=st.method or cfg.method,
        divergence_threshold=cfg.divergence_threshold,
        draws=robust_draws,
        noise_realisations=st.noise_realisations,
        expected_candidates=st.population * st.generations,
    )
    if st.noise_realisations > 1 and not _noisy(cfg):
        raise ConfigError(
            f"tune.noise_realisations = {st.noise_realisations} but the measurement of "
            f"{source} has no noise; set [sensor] noise_variance (or [uncertainty] "
            "noise_variance), or noise_realisations = 1"
        )
    objective = Objective.from_settings(st, cfg)
    initial = _initial_population(space, cfg, st)
    fp_settings = st.model_dump(exclude={"generations", "chunks"}, mode="json")
    if fp_settings.get("robust") and not fp_settings["robust"]["corners"]:
        del fp_settings["robust"]["corners"]  # checkpoints from before the option resume
    fp_data = {
        "format": CHECKPOINT_FORMAT,
        "spec": spec.key(),
        "settings": fp_settings,
        "initial": hashlib.sha256(initial.tobytes()).hexdigest(),
        "coefficients": objective.coefficients.tolist(),
    }
    fingerprint = hashlib.sha256(json.dumps(fp_data, sort_keys=True).encode()).hexdigest()
    return Prepared(cfg, st, space, spec, objective, initial, fingerprint, source, notes)


def _robust_draws(
    cfg: RunConfig,
    st: TuneSettings,
    draws: Sequence[Mapping[str, Any]] | None,
    source: str,
) -> tuple[Mapping[str, Any], ...]:
    """The K scenario changes a robust run scores every candidate on (given or drawn, then
    the box corners with ``robust.corners``); none for a run that is not robust."""
    from aiofl.config import ConfigError

    if st.robust is None:
        if draws is not None:
            raise ConfigError("draws given but the [tune] table has no robust = {...} setting")
        return ()
    dt = st.dt or cfg.dt
    out: tuple[Mapping[str, Any], ...]
    out = draw_fields(cfg, st.robust.draws, dt) if draws is None else tuple(dict(d) for d in draws)
    if len(out) != st.robust.draws:
        raise ConfigError(f"tune.robust.draws = {st.robust.draws} but {len(out)} draws given")
    if st.robust.corners:  # the box corners after the draws (given or drawn)
        out += draw_fields(cfg, 0, dt, corners=True)
        k1 = (1 + len(out)) * st.noise_realisations
        if st.population * k1 > MAX_POPULATION:
            raise ConfigError(
                f"invalid [tune] of {source}: population x (robust.draws + corners + 1) "
                f"x noise_realisations = {st.population} x {k1} = {st.population * k1} "
                f"members per generation; allowed: at most {MAX_POPULATION} (one "
                "batched engine call)"
            )
    return out


def _noisy(cfg: RunConfig) -> bool:
    """Whether the config's measurement has noise (its own or a drawn variance)."""
    unc = cfg.uncertainty
    drawn = unc is not None and unc.noise_variance is not None and unc.noise_variance[1] > 0
    return cfg.scenario.noise_variance > 0 or drawn


def draw_fields(
    config: Any, draws: int, dt: float, *, corners: bool = False
) -> tuple[dict[str, Any], ...]:
    """The K per-draw changes of ``config``'s ``[uncertainty]`` table, as plain data.

    Drawn by :func:`aiofl.uncertainty.sample_draws` with the table's seed and ``draws`` =
    K (common random numbers: the same for every candidate and every run with that seed);
    ``corners`` appends the box corners (:func:`aiofl.uncertainty.corner_draws`), so
    ``draws == 0`` with ``corners`` gives the corners alone.
    Each draw is a dict of :class:`aiofl.scenario.Scenario` fields that differ from the
    nominal scenario (``plant_scale``, ``noise_variance`` ...), plus ``"ts"`` when the
    sample time is drawn, so it travels to Dask workers in the picklable evaluation spec.
    Raises :class:`aiofl.config.ConfigError` when the config has no ``[uncertainty]`` table.

    Parameters
    ----------
    config
        The run config.
    draws
        K, the number of draws (0: none).
    dt
        The config's step [s] (a drawn sample time is a multiple of it).
    corners
        Append the box corners.

    Returns
    -------
    tuple of dict
    """
    from dataclasses import fields

    from aiofl.config import ConfigError
    from aiofl.uncertainty import corner_draws, sample_draws

    unc = getattr(config, "uncertainty", None)
    if unc is None:
        raise ConfigError(
            "tune.robust: needs the config's [uncertainty] table (the model error to be "
            "robust against), e.g. [uncertainty] parameters = { J_l = { uniform = 0.2 } }"
        )
    try:
        if corners:
            c = corner_draws(unc, dt=dt)[0]
            d = c if draws == 0 else sample_draws(unc, draws=draws, dt=dt).concat(c)
        else:
            d = sample_draws(unc, draws=draws, dt=dt)
        scenarios = d.scenarios(config.scenario)
    except ValueError as exc:
        raise ConfigError(f"tune.robust: {exc}") from None
    nominal = config.scenario
    out = []
    for k, s in enumerate(scenarios):
        diff: dict[str, Any] = {}
        for f in fields(s):
            v, v0 = getattr(s, f.name), getattr(nominal, f.name)
            if f.name == "t_final" or v == v0:
                continue
            diff[f.name] = dict(v) if f.name in ("plant_scale", "plant_overrides") else v
        if d.ts is not None:
            diff["ts"] = float(d.ts[k])
        out.append(diff)
    return tuple(out)
