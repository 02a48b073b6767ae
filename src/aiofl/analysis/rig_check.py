r"""A design on a rig: what a user gets when the design leaves the model for a real loop.

:func:`rig_check` puts a design on a rig preset (:data:`aiofl.rig.RIG_PRESETS`, by default
``"servo-1khz"``: a 12-bit encoder sampled at 1 ms, one sample of measurement delay, a
1 ms actuator lag, 1 % Coulomb friction at the plant's input) and runs it

* on the **nominal plant** with the rig: the figures a user sees on the bench;
* over **draws** of the design's own ``[uncertainty]`` box (for a design without one,
  ±20 % of every plant parameter; or one ``box`` for every design judged together) *and*
  of the rig's unmodelled dynamics, :data:`RIG_DRAWS` (the actuator lag and the friction
  each × U[0.5, 1.5]): what a plant nobody measured exactly does with it.

The design is run **as shipped**: a controller that was not told about the rig's delay
(``[controller.eso] delay``) is not told now; ``told=True`` tells it (``delay = "rig"``).
A continuous design runs sampled at the rig sensor's Ts.

**The verdict says what the plant did** (:meth:`RigCheck.verdict`): ``"holds"`` (the
nominal run and every draw neither lost nor diverged, the command not screaming),
``"does not track"`` (held, but its ITAE is at least :data:`NO_TRACKING` of the ITAE of no
control at all, :math:`y \equiv 0`: :math:`\int_0^{t_f} t\,|r|\,dt`), ``"screams"`` (the
plant is held, but at steady state the command is mostly the encoder's quantum,
:func:`aiofl.engine.response.screaming`), ``"command ×N"`` (held, but its ISU is more
than :data:`ISU_FACTOR` times the design's own run's: the rig's quantum, delay or lag drive
the actuator far beyond what the design was judged with), ``"lost in k of N draws"``
(joined by "; " when several are true), or the nominal run's own ``"lost at t = …"`` /
``"diverged at t = …"``.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from aiofl import layout as L

__all__ = [
    "FRICTION_STATES",
    "RIG_DRAWS",
    "RigCheck",
    "no_control_itae",
    "rig_check",
    "rig_checks",
    "rig_config",
]

#: the rig's own quantities drawn with the plant's parameters (factors on the rig's values)
RIG_DRAWS: dict[str, dict[str, float]] = {
    "rig_lag": {"uniform": 0.5},
    "rig_coulomb": {"uniform": 0.5},
}

#: the velocity state friction opposes, for the shipped plants (a rig preset cannot know it)
FRICTION_STATES: dict[str, str] = {
    "slfjm": "theta_dot",
    "dcmotor_arm": "omega",
    "flexjoint_hub": "w_m",
}

#: a held design whose ITAE is at least this share of no control's (y = 0) does not track
NO_TRACKING = 0.5

#: a held design whose command energy (ISU) on the rig exceeds this multiple of its own run's
ISU_FACTOR = 2.0

#: the parameter box used when a design has no [uncertainty] table: ±20 % of every parameter
DEFAULT_BOX = 0.2


def rig_config(
    cfg: Any,
    rig: str = "servo-1khz",
    *,
    friction_state: str | None = None,
    told: bool = False,
    draws: int | None = None,
    seed: int | None = None,
    box: dict[str, float] | None = None,
) -> Any:
    """``cfg`` on the rig preset ``rig``, with an ``[uncertainty]`` table that draws the
    plant's box and the rig's :data:`RIG_DRAWS`.

    Parameters
    ----------
    cfg : RunConfig
        The design as shipped.
    rig : str
        A rig preset (:data:`aiofl.rig.RIG_PRESETS`).
    friction_state : str, optional
        The plant state friction opposes; default :data:`FRICTION_STATES` by plant name,
        and no friction for a plant not listed there (said in :attr:`RigCheck.notes`).
    told : bool
        Tell the controller the rig's measurement delay (``[controller.eso] delay =
        "rig"``); a design already told keeps its own value either way.
    draws, seed : int, optional
        The ``[uncertainty]`` table's draws and seed (default: the design's own, else 32
        draws and seed 0).
    box : dict, optional
        ``{parameter: p}``: draw each as a factor ~ U[1 - p, 1 + p] *instead of* the
        design's own ``[uncertainty.parameters]`` (so designs judged together meet the
        same plants).

    Returns
    -------
    RunConfig
        Validated like a file (:func:`aiofl.config.parse_config`); raises
        :class:`~aiofl.config.ConfigError` when the design cannot run on the rig.
    """
    from aiofl.config import parse_config
    from aiofl.rig import Rig

    data = copy.deepcopy(cfg.raw)
    table: dict[str, Any] = {"preset": rig}
    plant_name = data["plant"] if isinstance(data.get("plant"), str) else cfg.plant.name
    state = friction_state or FRICTION_STATES.get(plant_name)
    preset = Rig.from_preset(rig, friction_state="v")
    has_friction = preset.has_friction
    if has_friction:
        if state is None:
            table["coulomb"] = 0.0
        else:
            table["friction_state"] = state
    data["rig"] = table
    old = data.get("sensor") if isinstance(data.get("sensor"), dict) else {}
    noise = {k: v for k, v in old.items() if k.startswith("noise_")}
    data.pop("sensor", None)
    if noise:
        data["sensor"] = noise
    if isinstance(data.get("controller"), dict):
        discrete = data["controller"].get("discrete")
        if isinstance(discrete, dict):  # the rig's sensor sets the sample time and quantum
            for key in ("ts", "y_quantum"):
                discrete.pop(key, None)
        if told:
            eso = data["controller"].setdefault("eso", {})
            eso.setdefault("delay", "rig")
    for key in ("output_delay", "input_delay"):
        if isinstance(data.get("scenario"), dict):
            data["scenario"].pop(key, None)
    unc = copy.deepcopy(data.get("uncertainty") or {})
    params = dict(unc.get("parameters") or {})
    if box is not None:
        params = {name: {"uniform": p} for name, p in box.items()}
    params = {k: v for k, v in params.items() if not k.startswith("rig_")}  # the new rig's
    if not params:
        names = [n for n in cfg.plant.param_names if not n.startswith("rig_")]
        params = {name: {"uniform": DEFAULT_BOX} for name in names}
    present = {"rig_lag": preset.lag > 0.0, "rig_coulomb": has_friction and state is not None}
    params.update({k: v for k, v in RIG_DRAWS.items() if present[k]})
    unc["parameters"] = params
    unc["draws"] = draws if draws is not None else int(unc.get("draws", 32))
    unc["seed"] = seed if seed is not None else int(unc.get("seed", 0))
    data["uncertainty"] = unc
    return parse_config(data, f"{cfg.name} on rig {rig}")


@dataclass(frozen=True)
class RigCheck:
    r"""A design on a rig (:func:`rig_check`).

    Attributes
    ----------
    name, rig
        The design's and the rig's names.
    nominal
        The nominal plant's run: ``itae``, ``isu``, ``status``, ``stopped_at``, ``u_peak``,
        ``screaming``.
    own
        The design's own run as shipped (its own sensor, no rig): ``itae``, ``isu``,
        ``status``.
    draws, status_counts
        Number of draws (0 when the nominal run already failed) and how many were ok /
        lost / diverged.
    not_lost
        Share of the draws neither lost nor diverged (None without draws).
    itae_q50, itae_q95, isu_q95
        Over the draws (None where a lost or diverged draw falls, or without draws).
    told
        Whether the controller knows the rig's measurement delay.
    no_control_itae
        The ITAE of no control at all, :math:`\int_0^{t_f} t\,|r|\,dt` (y ≡ 0).
    notes
        What was assumed (no friction state known, ...).
    """

    name: str
    rig: str
    nominal: dict[str, Any]
    own: dict[str, Any]
    draws: int
    status_counts: dict[str, int]
    not_lost: float | None
    itae_q50: float | None
    itae_q95: float | None
    isu_q95: float | None
    told: bool
    no_control_itae: float = float("inf")
    notes: list[str] = field(default_factory=list)

    @property
    def verdict(self) -> str:
        """What the plant did on the rig, in words (module docstring)."""
        nom = self.nominal
        if nom["status"] != "ok":
            return f"{nom['status']} at t = {nom['stopped_at']:.3g} s"
        said = []
        own = self.own.get("isu")
        share = nom["itae"] / self.no_control_itae
        if share >= NO_TRACKING:
            said.append(f"does not track (ITAE {100 * share:.0f} % of no control's)")
        if nom["screaming"]:
            said.append("screams")
        elif own is not None and own > 0 and nom["isu"] > ISU_FACTOR * own:
            said.append(f"command ×{nom['isu'] / own:.3g}")
        bad = self.draws - self.status_counts.get("ok", 0)
        if bad:
            said.append(f"lost in {bad} of {self.draws} draws")
        return "; ".join(said) or "holds"

    @property
    def holds(self) -> bool:
        """The design holds on the rig: nominal and every draw kept, command not screaming."""
        return self.verdict == "holds"

    def to_dict(self) -> dict[str, Any]:
        """A JSON record (no NaN: None)."""
        return {
            "name": self.name,
            "rig": self.rig,
            "told": self.told,
            "verdict": self.verdict,
            "nominal": self.nominal,
            "own": self.own,
            "draws": self.draws,
            "status_counts": self.status_counts,
            "not_lost": self.not_lost,
            "itae_q50": self.itae_q50,
            "itae_q95": self.itae_q95,
            "isu_q95": self.isu_q95,
            "no_control_itae": self.no_control_itae,
            "notes": self.notes,
        }


def no_control_itae(cfg: Any) -> float:
    r"""The ITAE of no control at all (:math:`y \equiv 0`), :math:`\int_0^{t_f} t\,|r|\,dt`,
    by the trapezoid rule on the run's step from the scenario's reference."""
    from aiofl.components.metrics import itae

    t_f = cfg.scenario.t_final
    t = np.linspace(0.0, t_f, round(t_f / cfg.dt) + 1)
    return float(itae(t, np.zeros_like(t), cfg.scenario.reference.evaluate(t)))


def _record(metrics: Any, status: str, stopped_at: float) -> dict[str, Any]:
    ok = status == "ok"
    return {
        "itae": float(metrics[L.METRIC_NAMES.index("itae")]) if ok else None,
        "isu": float(metrics[L.METRIC_NAMES.index("isu")]) if ok else None,
        "status": status,
        "stopped_at": None if ok else float(stopped_at),
    }


def _share_plants(cfgs: list[Any]) -> list[Any]:
    """The configs with one plant object per equal plant (same name, states and
    parameters), so :func:`~aiofl.analysis.robustness_draws.simulate_designs` and the nominal
    runs batch designs of the same plant into one engine call."""
    from dataclasses import replace

    seen: dict[tuple[Any, ...], Any] = {}
    out = []
    for cfg in cfgs:
        p = cfg.plant
        key = (p.name, p.n_states, tuple(sorted(p.params.items())))
        out.append(replace(cfg, plant=seen.setdefault(key, p)))
    return out


def _nominal_runs(cfgs: list[Any]) -> list[tuple[dict[str, Any], dict[str, float]]]:
    """Every config's own run (batched by plant, scenario, horizon, step and method):
    its record and its response figures."""
    from aiofl.engine.simulation import simulate_batch

    groups: list[list[int]] = []
    for i, cfg in enumerate(cfgs):
        for idx in groups:
            first = cfgs[idx[0]]
            if (
                first.plant is cfg.plant
                and first.scenario == cfg.scenario
                and (first.dt, first.method, first.divergence_threshold)
                == (cfg.dt, cfg.method, cfg.divergence_threshold)
            ):
                idx.append(i)
                break
        else:
            groups.append([i])
    out: dict[int, tuple[dict[str, Any], dict[str, float]]] = {}
    for idx in groups:
        base = cfgs[idx[0]]
        samplings = [cfgs[i].sampling for i in idx]
        res = simulate_batch(
            base.plant,
            [cfgs[i].controller for i in idx],
            [base.scenario] * len(idx),
            dt=base.dt,
            method=base.method,
            divergence_threshold=base.divergence_threshold,
            sampling=samplings if any(s is not None for s in samplings) else None,
        )
        for j, i in enumerate(idx):
            status = L.STATUS_NAMES[int(res.status[j])]
            figures = {k: float(v[j]) for k, v in res.response.items()}
            out[i] = (_record(res.metrics[j], status, res.stopped_at[j]), figures)
    return [out[i] for i in range(len(cfgs))]


def rig_checks(
    cfgs: list[Any],
    rig: str = "servo-1khz",
    *,
    draws: int = 32,
    seed: int = 0,
    told: bool = False,
    box: dict[str, float] | None = None,
    own: dict[str, dict[str, Any]] | None = None,
    skipped: dict[str, str] | None = None,
) -> list[RigCheck]:
    """Run designs on a rig, nominal and over draws (module docstring), batched: designs
    of one plant and scenario share each engine call.

    Parameters
    ----------
    cfgs : list of RunConfig
        The designs as shipped (names unique).
    rig : str
        A rig preset (:data:`aiofl.rig.RIG_PRESETS`).
    draws : int
        Draws of the parameter box and the rig's :data:`RIG_DRAWS` (0: the nominal run
        only).  Designs with the same box meet the same draws (common random numbers).
    seed : int
        The draws' seed.
    told : bool
        Tell every controller the rig's measurement delay.
    box : dict, optional
        One parameter box for every design (:func:`rig_config`); default each design's own.
    own : dict, optional
        The designs' own runs as shipped by name (``itae``, ``isu``, ``status``,
        ``stopped_at``), when the caller has them; the others are run.
    skipped : dict, optional
        Filled with why a design cannot go on the rig (by name), and the design left out;
        without it such a design raises :class:`~aiofl.config.ConfigError`.

    Returns
    -------
    list of RigCheck
        In the order of ``cfgs`` (those left out by ``skipped`` omitted).
    """
    from aiofl.analysis.robustness_draws import simulate_designs
    from aiofl.engine.response import screaming
    from aiofl.uncertainty import sample_draws

    own = {
        name: {k: rec.get(k) for k in ("itae", "isu", "status", "stopped_at")}
        for name, rec in (own or {}).items()
    }
    placed = []
    for c in cfgs:
        try:
            placed.append(
                (c, rig_config(c, rig, told=told, draws=max(draws, 1), seed=seed, box=box))
            )
        except ValueError as exc:  # ConfigError included
            if skipped is None:
                raise
            skipped[c.name] = str(exc).strip().splitlines()[-1].strip()
    cfgs = [c for c, _ in placed]
    missing = [c for c in cfgs if c.name not in own]
    for cfg, (rec, _) in zip(missing, _nominal_runs(_share_plants(missing)), strict=True):
        own[cfg.name] = rec
    on_rig = _share_plants([on for _, on in placed])
    nominal = _nominal_runs(on_rig)
    checks: dict[int, RigCheck] = {}
    by_box: dict[str, list[int]] = {}
    for i, (cfg, (rec, figures)) in enumerate(zip(on_rig, nominal, strict=True)):
        notes = []
        if cfg.rig is not None and cfg.rig.coulomb == 0.0 and rig != "ideal":
            notes.append(f"no friction: no velocity state known for plant {cfg.plant.name!r}")
        rec = {
            **rec,
            "u_peak": figures.get("u_peak"),
            "screaming": bool(figures) and screaming(figures),
        }
        checks[i] = RigCheck(
            name=cfgs[i].name,
            rig=rig,
            nominal=rec,
            own=own[cfgs[i].name],
            draws=0,
            status_counts={n: 0 for n in L.STATUS_NAMES.values()},
            not_lost=None,
            itae_q50=None,
            itae_q95=None,
            isu_q95=None,
            told=told,
            no_control_itae=no_control_itae(cfg),
            notes=notes,
        )
        if draws > 0 and rec["status"] == "ok":
            key = cfg.uncertainty.model_dump_json()
            by_box.setdefault(key, []).append(i)
    for idx in by_box.values():
        first = on_rig[idx[0]]
        d = sample_draws(first.uncertainty, dt=first.dt)
        for i, res in zip(idx, simulate_designs([on_rig[i] for i in idx], d), strict=True):
            rec = res.to_dict()
            base = checks[i]
            checks[i] = RigCheck(
                name=base.name,
                rig=rig,
                nominal=base.nominal,
                own=base.own,
                draws=len(d),
                status_counts=rec["status_counts"],
                not_lost=float(rec["stable_fraction"]),
                itae_q50=rec["itae"]["q50"],
                itae_q95=rec["itae"]["q95"],
                isu_q95=rec["isu"]["q95"],
                told=told,
                no_control_itae=base.no_control_itae,
                notes=base.notes,
            )
    return [checks[i] for i in range(len(cfgs))]


def rig_check(
    cfg: Any,
    rig: str = "servo-1khz",
    *,
    draws: int = 32,
    seed: int = 0,
    told: bool = False,
    box: dict[str, float] | None = None,
) -> RigCheck:
    """One design on a rig (:func:`rig_checks` of one design).

    Parameters
    ----------
    cfg : RunConfig
        The design as shipped.
    rig : str
        A rig preset (:data:`aiofl.rig.RIG_PRESETS`).
    draws : int
        Draws of the parameter box and the rig's :data:`RIG_DRAWS` (0: nominal only).
    seed : int
        The draws' seed.
    told : bool
        Tell the controller the rig's measurement delay.
    box : dict, optional
        ``{parameter: p}``, drawn × U[1 - p, 1 + p] instead of the design's own box.

    Returns
    -------
    RigCheck
    """
    return rig_checks([cfg], rig, draws=draws, seed=seed, told=told, box=box)[0]
