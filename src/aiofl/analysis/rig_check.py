r"""A design on a rig: what a user gets when the design leaves the model for a real loop.

:func:`rig_check` puts a design on a rig preset (:data:`aiofl.rig.RIG_PRESETS`, by default
``"servo-1khz"``: a 12-bit encoder sampled at 1 ms, one sample of measurement delay, a
1 ms actuator lag, 1 % Coulomb friction at the plant's input) and runs it

* on the **nominal plant** with the rig: the figures a user sees on the bench;
* over **draws** of the design's own ``[uncertainty]`` box (or ±20 % of every plant
  parameter the box does not name: none, if it has none) *and* of the rig's unmodelled
  dynamics, :data:`RIG_DRAWS` (the actuator lag and the friction each × U[0.5, 1.5]):
  what a plant nobody measured exactly does with it.

The design is run **as shipped**: a controller that was not told about the rig's delay
(``[controller.eso] delay``) is not told now; ``told=True`` tells it (``delay = "rig"``).
A continuous design runs sampled at the rig sensor's Ts.

**The verdict says what the plant did** (:meth:`RigCheck.verdict`): ``"holds"`` (the
nominal run and every draw neither lost nor diverged, the command not screaming),
``"screams"`` (the plant is held, but at steady state the command is mostly the encoder's quantum,
:func:`aiofl.engine.response.screaming`), ``"command ×N"`` (held, but its ISU is more
than :data:`ISU_FACTOR` times the design's own run's: the rig's quantum, delay or lag drive
the actuator far beyond what the design was judged with), ``"lost in k of N draws"`` (joined by
"; " when several are true), or the nominal run's own ``"lost at t = …"`` / ``"diverged at t = …"``.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from aiofl import layout as L

__all__ = ["FRICTION_STATES", "RIG_DRAWS", "RigCheck", "rig_check", "rig_config"]

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
    state = friction_state or FRICTION_STATES.get(cfg.plant.name)
    has_friction = Rig.from_preset(rig, friction_state="v").has_friction
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
    if not params:
        params = {name: {"uniform": DEFAULT_BOX} for name in cfg.plant.param_names}
    params.update({k: v for k, v in RIG_DRAWS.items() if k != "rig_coulomb" or state})
    unc["parameters"] = params
    unc["draws"] = draws if draws is not None else int(unc.get("draws", 32))
    unc["seed"] = seed if seed is not None else int(unc.get("seed", 0))
    data["uncertainty"] = unc
    data.pop("tune", None)
    return parse_config(data, f"{cfg.name} on rig {rig}")


@dataclass(frozen=True)
class RigCheck:
    """A design on a rig (:func:`rig_check`).

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
    draws
        Number of draws; ``status_counts`` how many were ok / lost / diverged.
    itae_q95, isu_q95
        Over the draws (None where a lost or diverged draw falls).
    told
        Whether the controller knows the rig's measurement delay.
    notes
        What was assumed (no friction state known, ...).
    """

    name: str
    rig: str
    nominal: dict[str, Any]
    own: dict[str, Any]
    draws: int
    status_counts: dict[str, int]
    not_lost: float
    itae_q50: float | None
    itae_q95: float | None
    isu_q95: float | None
    told: bool
    notes: list[str] = field(default_factory=list)

    @property
    def verdict(self) -> str:
        """What the plant did on the rig, in words (module docstring)."""
        nom = self.nominal
        if nom["status"] != "ok":
            return f"{nom['status']} at t = {nom['stopped_at']:.3g} s"
        said = []
        own = self.own.get("isu")
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
            "notes": self.notes,
        }


def _run_record(res: Any) -> dict[str, Any]:
    return {
        "itae": None if res.failed else float(res.metrics["itae"]),
        "isu": None if res.failed else float(res.metrics["isu"]),
        "status": str(res.status),
        "stopped_at": float(res.stopped_at) if res.failed else None,
    }


def rig_check(
    cfg: Any,
    rig: str = "servo-1khz",
    *,
    draws: int = 32,
    seed: int = 0,
    told: bool = False,
    friction_state: str | None = None,
) -> RigCheck:
    """Run a design on a rig, nominal and over draws (module docstring).

    Parameters
    ----------
    cfg : RunConfig
        The design as shipped.
    rig : str
        A rig preset.
    draws : int
        Draws of the parameter box and the rig's :data:`RIG_DRAWS` (0: the nominal run only).
    seed : int
        The draws' seed (common random numbers: every design meets the same plants).
    told : bool
        Tell the controller the rig's measurement delay.
    friction_state : str, optional
        The velocity state friction opposes (default: :data:`FRICTION_STATES`).

    Returns
    -------
    RigCheck
    """
    from aiofl.analysis.robustness import run_robustness
    from aiofl.engine.response import screaming

    on_rig = rig_config(
        cfg, rig, friction_state=friction_state, told=told, draws=max(draws, 1), seed=seed
    )
    notes = []
    if on_rig.rig is not None and on_rig.rig.coulomb == 0.0 and rig != "ideal":
        notes.append(f"no friction: no velocity state known for plant {cfg.plant.name!r}")
    res = on_rig.simulate(store=False)
    figures = res.response or {}
    nominal = {
        **_run_record(res),
        "u_peak": float(figures.get("u_peak", np.nan)) if figures else None,
        "screaming": bool(figures) and screaming(figures),
    }
    own = _run_record(cfg.simulate(store=False))
    if draws == 0 or res.failed:
        counts = {name: 0 for name in L.STATUS_NAMES.values()}
        return RigCheck(cfg.name, rig, nominal, own, 0, counts, float("nan"), None, None,
                        None, told, notes)  # fmt: skip
    rob = run_robustness(on_rig, draws=draws, seed=seed)
    d = rob.to_dict()
    return RigCheck(
        name=cfg.name,
        rig=rig,
        nominal=nominal,
        own=own,
        draws=draws,
        status_counts=d["status_counts"],
        not_lost=float(d["stable_fraction"]),
        itae_q50=d["itae"]["q50"],
        itae_q95=d["itae"]["q95"],
        isu_q95=d["isu"]["q95"],
        told=told,
        notes=notes,
    )
