"""The notebook API: one object from ``Plant`` + ``Controller`` + ``Scenario`` to every command.

:class:`Design` holds a plant (built-in or defined in Python), a controller and a scenario
with the run settings, validated exactly as a TOML config is (it builds one, with a
``raw`` dict that round-trips through :func:`aiofl.config.parse_config`:
:mod:`aiofl.config.objects`), and offers what the command line does::

    d = Design(plant, controller, scenario, dt=1e-3)
    d.simulate()                                        # aiofl simulate
    result = d.tune({"eso.omega0": (10, 200)}, population=16, generations=5)  # aiofl tune
    tuned = d.with_values(result.best_values)
    tuned.robustness(draws=32)                          # aiofl robustness
    tuned.analyze()                                     # aiofl analyze --closed-loop
    tuned.export("out", ts=1e-3)                        # aiofl export

A bad value raises ``ValueError`` (a :class:`aiofl.config.ConfigError` from the config
checks) naming the field and the allowed range, as the command line's exit 2 does.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from aiofl.components.metrics import OPIWeights
from aiofl.config import RunConfig
from aiofl.config.objects import run_config_from_objects
from aiofl.controller import Controller
from aiofl.plants.base import Plant
from aiofl.scenario import Scenario

__all__ = ["Design"]


@dataclass(frozen=True)
class Design:
    """A plant, a controller and a scenario with the run settings, validated like a config.

    Parameters
    ----------
    plant
        An :class:`aiofl.Plant`: a registered one (``aiofl.get_plant("pendulum")``) or
        one defined in Python, which is registered in this process under its name (so the
        tuner, which rebuilds the config from its dict, finds it; see
        :mod:`aiofl.config.objects`).
    controller, scenario
        The :class:`aiofl.Controller` and :class:`aiofl.Scenario`.
    dt, method, decimation, divergence_threshold
        The ``[simulation]`` settings.
    sampling
        An :class:`aiofl.engine.discrete_rows.Sampling` (``[controller.discrete]``): run the
        controller sampled; None: continuous (or the sensor's sample time).
    sensor
        A sensor preset name (``"encoder-12bit"``) or an :class:`aiofl.sensor.Sensor`
        (``[sensor]``); None: the scenario's own measurement.
    uncertainty
        The ``[uncertainty]`` table as a dict (``{"draws": 32, "parameters": {"m":
        {"uniform": 0.2}}}``) or an :class:`aiofl.uncertainty.UncertaintyModel`, for
        :meth:`robustness` and robust tuning.
    weights
        The OPI weights (:class:`aiofl.OPIWeights`; default the paper's).
    name, description
        Labels (reports, ``best.toml``, the C files' comment block).

    Raises
    ------
    ValueError
        A :class:`aiofl.config.ConfigError` naming the field and its allowed range.
    """

    plant: Plant
    controller: Controller
    scenario: Scenario
    dt: float = 1e-4
    method: str = "rk4"
    decimation: int = 10
    divergence_threshold: float = 1e10
    sampling: Any = None
    sensor: Any = None
    uncertainty: Any = None
    weights: OPIWeights | None = None
    name: str = "design"
    description: str = ""
    config: RunConfig = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        cfg = run_config_from_objects(
            self.plant,
            self.controller,
            self.scenario,
            dt=self.dt,
            method=self.method,
            decimation=self.decimation,
            divergence_threshold=self.divergence_threshold,
            sampling=self.sampling,
            sensor=self.sensor,
            uncertainty=self.uncertainty,
            weights=self.weights,
            name=self.name,
            description=self.description,
        )
        # the objects given, not their rebuilt copies (the same values, checked)
        object.__setattr__(
            self, "config", replace(cfg, plant=self.plant, controller=self.controller)
        )

    # ------------------------------------------------------------------ variants
    def with_values(self, values: Mapping[str, float] | None = None, **kw: float) -> Design:
        """A copy with controller parameters replaced (e.g. a tuning result's
        ``best_values``; dotted names also as ``**{"eso.omega0": 80}``)."""
        merged = {**(values or {}), **kw}
        return replace(self, controller=self.controller.with_values(**merged))

    def replace(self, **changes: Any) -> Design:
        """A copy with fields replaced (``scenario=...``, ``dt=...``, ``sensor=...``),
        validated again."""
        return replace(self, **changes)

    # ------------------------------------------------------------------ saving
    def to_toml(self, path: str | Path | None = None, *, python_plant: bool = False) -> str:
        """This design as a run config's TOML text (written with tomlkit); with ``path``
        also written there (atomically; a plant file is then named relative to the
        file's folder), so ``aiofl simulate PATH`` (and every command) runs it.

        The plant must be one a config can name: a shipped or registered plant, or one built
        from a plant file (:func:`aiofl.config.resolve_plant`: named by its path).  A plant
        defined in Python is known only in the process that defined it: refused (a
        ``ValueError`` saying what to do) unless ``python_plant`` is true, when the file
        loads only in a Python process that registers the plant first
        (``aiofl.register_plant(NAME, lambda: plant)``).
        """
        import copy
        import os

        import tomlkit

        from aiofl.config.objects import is_python_plant
        from aiofl.outputs import atomic_write_text
        from aiofl.plants.registry import python_plant_hint

        data = copy.deepcopy(dict(self.config.raw))
        plant = str(data["plant"])
        python = is_python_plant(plant)
        if python and not python_plant:
            raise ValueError(
                f"plant {plant!r} is defined in Python: a saved config naming it runs only in a "
                "Python process that registers it first. Write the plant as a plant file and "
                "build the Design from aiofl.config.resolve_plant('FILE.toml') (the file then "
                "runs anywhere), or pass python_plant=True to save it anyway"
            )
        if path is not None and plant.endswith(".toml"):
            folder = Path(path).resolve().parent
            data["plant"] = Path(os.path.relpath(plant, folder)).as_posix()
        doc = tomlkit.document()
        doc.add(tomlkit.comment(f"aiofl design {self.name!r}, saved by aiofl.Design.to_toml"))
        if python:
            doc.add(tomlkit.comment(python_plant_hint(plant)))
        for key, value in data.items():
            doc[key] = value
        text = tomlkit.dumps(doc)
        if path is not None:
            atomic_write_text(Path(path), text)
        return text

    def save(self, path: str | Path, *, python_plant: bool = False) -> Path:
        """Write this design as a run config to ``path`` (:meth:`to_toml`); returns it."""
        self.to_toml(path, python_plant=python_plant)
        return Path(path)

    # ------------------------------------------------------------------ commands
    def simulate(self, *, store: bool = True) -> Any:
        """One run (``aiofl simulate``): a :class:`aiofl.engine.simulation.SimulationResult`
        (``.metrics``, ``.failed``, ``.t``, ``["y"]``, ``.opi(weights)``)."""
        return self.config.simulate(store=store)

    def opi(self) -> float | None:
        """The OPI (eq. 22) of one run with this design's weights; None if it diverged."""
        return self.simulate(store=False).opi(self.config.weights)

    def tune(
        self,
        parameters: Mapping[str, Any],
        *,
        progress: bool = False,
        out: str | Path | None = None,
        checkpoint_dir: str | Path | None = None,
        resume: bool = False,
        evaluator: Any = None,
        **settings: Any,
    ) -> Any:
        """Tune the controller (``aiofl tune``): :func:`aiofl.tuning.search.tune`.

        Parameters
        ----------
        parameters
            The tuned parameters and their bounds, as ``[tune.parameters]``:
            ``{"eso.omega0": (10, 200)}`` or ``{"eso.omega0": {"lo": 10, "hi": 200,
            "log": True}}``.
        progress, checkpoint_dir, resume, evaluator
            As for :func:`aiofl.tuning.search.tune` (a Python-defined plant is known in
            this process only: tune it locally, the default, not on Dask workers).
        out
            Also write the tuning outputs there (``best.toml``, ``evaluations.csv``,
            figures: :func:`aiofl.tuning.results.write_outputs`).
        **settings
            The other ``[tune]`` settings (``population``, ``generations``, ``t_final``,
            ``seed``, ``objective``, ``robust``, ``algorithm`` ...).

        Returns
        -------
        aiofl.tuning.search.TuneResult
            ``best_values`` (apply with :meth:`with_values`), ``best_objective``,
            ``best_metrics``, the history and every evaluation.
        """
        from aiofl.tuning.search import tune

        table = {"parameters": {k: _bounds(v) for k, v in parameters.items()}, **settings}
        result = tune(
            self.config,
            table,
            progress=progress,
            checkpoint_dir=checkpoint_dir,
            resume=resume,
            evaluator=evaluator,
        )
        if out is not None:
            from aiofl.tuning.results import write_outputs

            write_outputs(result, out)
        return result

    def robustness(self, *, draws: int | None = None, seed: int | None = None) -> Any:
        """The design over the draws of its ``uncertainty`` (``aiofl robustness``): an
        :class:`aiofl.analysis.robustness_draws.RobustnessResult` (``stable_fraction``,
        ``quantiles(itae)``, ``to_dict()``;
        :func:`~aiofl.analysis.robustness_draws.robustness_figure` draws it).  ``draws`` /
        ``seed`` override the table's."""
        from aiofl.analysis.robustness_draws import run_robustness

        if self.config.uncertainty is None:
            raise ValueError(
                "uncertainty: this design has none; give Design(..., uncertainty={'draws': "
                "32, 'parameters': {NAME: {'uniform': 0.2}}}) (the [uncertainty] table)"
            )
        return run_robustness(self.config, draws=draws, seed=seed)

    def analyze(self, *, amplitude: float = 1e-3, r_op: float | None = None) -> dict[str, Any]:
        """The linearised closed loop (``aiofl analyze --closed-loop``): verdict,
        eigenvalues, damping and margins as a dict
        (:func:`aiofl.analysis.linearize.closed_loop_verdict`; with ``r_op`` the
        linearisation at that reference value).  For a sampled design those are the
        continuous loop's (``"margins_of"``) and ``"sampled_loop"`` holds the sampled
        loop's verdict and margins (:func:`aiofl.analysis.sampled_loop.sampled_margins`)."""
        import math

        from aiofl.analysis.linearize import closed_loop_verdict, linearize_closed_loop

        if not (isinstance(amplitude, (int, float)) and math.isfinite(amplitude) and amplitude > 0):
            raise ValueError(f"amplitude = {amplitude!r}; allowed: a finite number, > 0")
        if r_op is not None and not math.isfinite(r_op):
            raise ValueError(f"r_op = {r_op!r}; allowed: a finite number")
        lin = linearize_closed_loop(self.config, amplitude=amplitude, r_op=r_op)
        if r_op is not None:
            return dict(lin.to_dict())
        out = closed_loop_verdict(self.config, amplitude=amplitude, linearization=lin)
        if self.config.sampling is not None:  # the margins above are the continuous loop's
            from aiofl.analysis.sampled_loop import sampled_margins

            out["margins_of"] = "the continuous loop (no sampling)"
            out["sampled_loop"] = sampled_margins(self.config)
        return out

    def export(
        self,
        out: str | Path,
        *,
        ts: float | None = None,
        precision: str = "double",
        prefix: str = "aiofl",
        format: str = "c",  # the CLI's --format
    ) -> dict[str, Path]:
        """Write the controller (``aiofl export``), sampled at ``ts`` (default: the
        design's sampling), in ``out``; returns the paths by file name.

        ``format = "c"``: C99 sources, ``PREFIX_controller.h``, ``PREFIX_controller.c`` and
        ``PREFIX_params.c`` (and ``PREFIX_model.h`` for a model-assisted controller);
        ``format = "fmu"``: ``PREFIX.fmu``, an FMI 2.0 co-simulation FMU of the same C
        (built with the C compiler, ``$CC`` or ``cc``).  Raises ``ValueError`` for what the
        C code cannot express, a bad prefix or format, or no compiler for an FMU
        (:class:`aiofl.export.ExportError`); nothing is written then.  Unlike ``aiofl
        export`` it runs no simulation first.

        Parameters
        ----------
        out
            The folder to write into (created if missing).
        ts
            Sample time [s], a number in [1e-9, 1]; default (None) the design's sampling, which
            an FMU needs.
        precision
            ``"double"`` (default) or ``"float"``: the C type of every number.
        prefix
            The C identifier every exported name starts with (default ``"aiofl"``).
        format
            ``"c"`` (default): the C99 sources; ``"fmu"``: one FMI 2.0 co-simulation FMU.

        Returns
        -------
        dict of str to Path
            The written files by file name.
        """
        from aiofl.engine.discrete_rows import Sampling
        from aiofl.export import ExportError, export_c
        from aiofl.export.fmu import export_fmu_for_config
        from aiofl.outputs import atomic_write_bytes, atomic_write_text

        cfg = self.config
        if ts is not None:
            from aiofl.engine.sample_time import check_ts

            ts = check_ts(ts, "ts")  # a number in [1e-9, 1] s (True refused)
            sampling = replace(cfg.sampling or Sampling(ts), ts=ts)
        else:
            sampling = cfg.sampling
        if precision not in ("double", "float"):
            raise ValueError(f"precision = {precision!r}; allowed: double, float")
        if format not in ("c", "fmu"):
            raise ValueError(f"format = {format!r}; allowed: c, fmu")
        files: dict[str, str | bytes]
        try:
            if format == "fmu":
                if sampling is None:
                    raise ExportError("no sample time: give ts or the design a sampling")
                name, data = export_fmu_for_config(
                    cfg, sampling, precision=precision, config=cfg.name, prefix=prefix
                )
                files = {name: data}
            else:
                files = export_c(
                    cfg.controller,
                    sampling,
                    precision=precision,
                    prefix=prefix,
                    title=cfg.name,
                    notes=[cfg.description] if cfg.description else [],
                    plant=cfg.plant,
                    plant_source=cfg.plant.name,
                    x0=cfg.scenario.x0,
                )
        except ExportError as exc:
            raise ValueError(f"cannot export {cfg.name!r}: {exc}") from None
        folder = Path(out)
        folder.mkdir(parents=True, exist_ok=True)
        paths = {}
        for name, content in files.items():
            if isinstance(content, bytes):
                atomic_write_bytes(folder / name, content)
            else:
                atomic_write_text(folder / name, content)
            paths[name] = folder / name
        return paths


def _bounds(value: Any) -> Any:
    """``(lo, hi)`` or ``(lo, hi, log)`` as the ``[tune.parameters]`` table's ``{lo, hi, log}``."""
    if isinstance(value, (tuple, list)) and len(value) in (2, 3):
        table = {"lo": value[0], "hi": value[1]}
        if len(value) == 3:
            table["log"] = value[2]
        return table
    return value
