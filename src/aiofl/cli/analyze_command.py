"""``aiofl analyze``: symbolic analysis of a plant, or closed-loop linearisation of a config.

* ``aiofl analyze PLANT`` (a built-in plant such as ``slfjm``, a symbolic-plant TOML, or a
  run config whose plant is analysed): Lie derivatives, relative degree and where it is
  defined, α, β, the normal-form coordinates ξ and, where ρ < n, the zero dynamics with a
  stability verdict (Section III).  ``--latex`` prints LaTeX, ``--json`` JSON.
* ``aiofl analyze CONFIG.toml|PRESET --sampling``: the largest sample time at which the
  design is stable (linearised sampled loop inside the unit circle, bounded run, off the
  saturation) and within 10 % of its continuous ITAE (:mod:`aiofl.cli.analyze_sampling`).
* ``aiofl analyze CONFIG.toml|PRESET --closed-loop``: eigenvalues of the closed loop
  linearised at its operating point (exact Jacobian; repeated ones with their
  multiplicity), slowest / fastest modes and a verdict (:mod:`aiofl.analysis.linearize`);
  the least damping ratio and the gain, phase and delay margins and sensitivity peak Ms of
  the loop broken at the plant input (:mod:`aiofl.analysis.frequency`); ``--json`` prints
  ``{"verdict": ..., "eigenvalues": [[re, im], ...], "gain_margin_db": ...,
  "phase_margin_deg": ..., "delay_margin_s": ..., "ms": ..., "min_damping": ..., ...}``;
  ``--figure FILE.png`` writes its Bode and Nyquist plots.  Unless ``--no-orbit``, also
  the reconciled verdict (:mod:`aiofl.analysis.orbit`): the limit cycle an unstable
  equilibrium settles on with r held (amplitudes, frequency, describing-function
  estimate), the tracking orbit's Floquet multipliers (sine) or largest finite-time
  Lyapunov exponent (step, samples); ``--json`` adds ``"orbit": {"equilibrium",
  "limit_cycle": {"amplitude_y", "amplitude_u", "frequency", "describing"}, "floquet":
  {"multipliers", "largest"}, "ftle", "verdict"}`` and ``"reconciled_verdict"``.  The
  continuous loop's disk margin (``"disk_margin"``, ``"disk_gain_margin_db"``,
  ``"disk_phase_margin_deg"``; :mod:`aiofl.analysis.loop_view`).  ``--loop-view`` adds the
  margin rows of the loop continuous and sampled, with ``--lag`` (actuator lag) and
  ``--measurement-delay`` (samples), disk margins and the noise in u (``"loop_view"``);
  ``--two-dof`` a linear ADRC's C and F (:mod:`aiofl.analysis.two_dof`, ``"two_dof"``).

sympy, numpy and the engine are imported inside the command, so registering it keeps
``aiofl --help`` fast.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated, Any

import typer

from aiofl.analysis.budget import DEFAULT_BUDGET
from aiofl.cli.bad_input import FORCE_OPTION

__all__ = ["analyze_command"]


def analyze_command(
    target: Annotated[
        str,
        typer.Argument(
            help="Plant name (e.g. slfjm), symbolic-plant TOML, or with --closed-loop a "
            "config TOML / preset name."
        ),
    ],
    closed_loop: Annotated[
        bool,
        typer.Option("--closed-loop", help="Linearise the whole closed loop of a config."),
    ] = False,
    latex: Annotated[bool, typer.Option("--latex", help="Print LaTeX (plant analysis).")] = False,
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON.")] = False,
    amplitude: Annotated[
        float,
        typer.Option(
            help="Error amplitude ε for the secant gains of fal / g(e) / INLSEF (--closed-loop)."
        ),
    ] = 1e-3,
    r_op: Annotated[
        float | None,
        typer.Option(help="Reference value held at the operating point (--closed-loop)."),
    ] = None,
    figure: Annotated[
        Path | None,
        typer.Option(
            help="Write the Bode and Nyquist plots of the loop broken at the plant input "
            "to this file (.png, .pdf or .svg; --closed-loop)."
        ),
    ] = None,
    sampling: Annotated[
        bool,
        typer.Option(
            "--sampling",
            help="Largest sample time Ts at which a config's design is stable (the "
            "linearised sampled loop has spectral radius < 1, the run stays bounded and off "
            "the saturation) and within --tolerance of its continuous ITAE (batched runs; "
            "see aiofl.analysis.sampling_limits).",
        ),
    ] = False,
    tolerance: Annotated[
        float, typer.Option(help="ITAE allowance over the continuous design (--sampling).")
    ] = 0.1,
    out: Annotated[
        Path | None,
        typer.Option("--out", "-o", help="With --sampling: write sampling.json, sampling.png."),
    ] = None,
    orbit: Annotated[
        bool,
        typer.Option(
            "--orbit/--no-orbit",
            help="With --closed-loop: also the limit cycle of an unstable equilibrium, the "
            "Floquet multipliers of the tracking orbit (or the largest Lyapunov exponent) and "
            "one reconciled verdict (aiofl.analysis.orbit).",
        ),
    ] = True,
    budget: Annotated[
        float,
        typer.Option(
            "--budget",
            help="Seconds the orbit analysis (--closed-loop) or the refining of the sample-"
            "time ladder (--sampling) may take; when spent it stops and the output says "
            "what it gave up.",
        ),
    ] = DEFAULT_BUDGET,
    two_dof: Annotated[
        bool,
        typer.Option(
            "--two-dof",
            help="With --closed-loop: a linear ADRC's equivalent 2-DOF form u = F·r − C·y, "
            "continuous and (if the config is sampled) discrete (aiofl.analysis.two_dof).",
        ),
    ] = False,
    loop_view: Annotated[
        bool,
        typer.Option(
            "--loop-view",
            help="With --closed-loop: margins (classical and disk) and noise-to-u of the loop "
            "continuous and as sampled, each row labelled with what it includes "
            "(aiofl.analysis.loop_view); implied by --lag, --measurement-delay, --noise-std.",
        ),
    ] = False,
    lag: Annotated[
        float,
        typer.Option("--lag", help="Actuator lag τ [s] in the loop-view rows (first order)."),
    ] = 0.0,
    measurement_delay: Annotated[
        int,
        typer.Option(
            "--measurement-delay", help="Samples of measurement delay in the loop-view rows."
        ),
    ] = 0,
    noise_std: Annotated[
        float | None,
        typer.Option(
            "--noise-std",
            help="Measurement noise σ per sample for the RMS of u (default: the config's "
            "noise and ADC quantum, q/√12).",
        ),
    ] = None,
    ceiling: Annotated[
        bool,
        typer.Option(
            "--ceiling",
            help="Only the observer bandwidth ceiling of a config: the caps on omega0 from "
            "the sample time, the loop delay and the sensor's noise, and the binding one "
            "(aiofl.analysis.observer_bandwidth); --closed-loop prints it too.",
        ),
    ] = False,
    u_scale: Annotated[
        float | None,
        typer.Option(
            "--u-scale",
            help="The command scale the noise cap compares the command's noise with "
            "(default: the actuator's half-range, else |u| holding the operating point).",
        ),
    ] = None,
    force: Annotated[bool, FORCE_OPTION] = False,
) -> None:
    """Analyse a plant symbolically (Section III), a closed loop by linearisation, or the
    sample times a design tolerates (--sampling).

    An existing --figure file or non-empty --out is refused unless --force."""
    import json

    from rich.console import Console

    from aiofl.cli.bad_input import bad_input_exits
    from aiofl.text import terminal_text

    if ceiling:
        _print_ceiling(target, u_scale, as_json=as_json, alone=True)
        return
    if sampling:
        from aiofl.cli.analyze_sampling import run_sampling

        with bad_input_exits():
            if closed_loop or latex or r_op is not None or figure is not None:
                raise ValueError(
                    "--sampling is not combined with --closed-loop, --latex, --r-op, --figure"
                )
            _check_budget_option(budget)
        run_sampling(
            target, as_json=as_json, out=out, tolerance=tolerance, force=force, budget=budget
        )
        return
    with bad_input_exits():
        if out is not None:
            raise ValueError("--out applies only with --sampling")

    from aiofl.analysis.numeric_warnings import numeric_warnings, warnings_note

    console = Console(highlight=False, markup=False, soft_wrap=True)
    with bad_input_exits(), numeric_warnings() as caught:  # numpy/scipy's: one note below
        if not (amplitude > 0 and math.isfinite(amplitude)):
            raise ValueError(f"--amplitude = {amplitude}; allowed: finite and > 0")
        if r_op is not None and not math.isfinite(r_op):
            raise ValueError(f"--r-op = {r_op}; allowed: a finite number")
        _check_budget_option(budget)
        want_view = loop_view or lag != 0.0 or measurement_delay != 0 or noise_std is not None
        if (want_view or two_dof) and not closed_loop:
            raise ValueError(
                "--two-dof, --loop-view, --lag, --measurement-delay and --noise-std apply "
                "only with --closed-loop"
            )
        if want_view:
            from aiofl.analysis.loop_view import check_loop_options

            try:
                check_loop_options(lag, measurement_delay, noise_std)
            except ValueError as exc:  # name the options as typed
                raise ValueError(
                    str(exc)
                    .replace("delay_samples", "--measurement-delay")
                    .replace("noise_std", "--noise-std")
                    .replace("lag =", "--lag =")
                ) from None
        if figure is not None:
            _check_figure_path(figure, closed_loop, force=force)
        if closed_loop:
            if latex:
                raise ValueError("--latex applies to the plant analysis, not to --closed-loop")
            from aiofl.analysis.linearize import (
                closed_loop_verdict,
                format_linearization_text,
                linearize_closed_loop,
            )
            from aiofl.cli.configs import load_run_config
            from aiofl.config import ConfigError, PlantFileGiven

            try:
                cfg = load_run_config(target)
            except PlantFileGiven:
                raise ConfigError(
                    f"{target} is a plant file; --closed-loop wants a run config (one that "
                    "names the plant and sets [scenario], [controller] and [simulation]); "
                    f"`aiofl analyze {target}` without --closed-loop analyses the plant itself"
                ) from None
            try:
                lin = linearize_closed_loop(cfg, amplitude=amplitude, r_op=r_op)
            except ValueError as exc:  # no operating point there: name the option that set it
                if r_op is None:
                    raise
                raise ValueError(
                    f"--r-op = {r_op:g}: {exc}; allowed: a reference value the loop can hold "
                    "(within the plant's range)"
                ) from None
            # the default operating point also gets the verdict per error amplitude
            info = (
                closed_loop_verdict(cfg, amplitude=amplitude, linearization=lin)
                if r_op is None
                else lin.to_dict()
            )
            if orbit and r_op is None:
                from aiofl.analysis.orbit import orbit_analysis

                info["orbit"] = orbit_analysis(cfg, info, unit=cfg.plant.output_unit, budget=budget)
                info["reconciled_verdict"] = info["orbit"]["verdict"]
            if as_json:  # the observer bandwidth ceiling (aiofl.analysis.observer_bandwidth)
                from aiofl.analysis.observer_bandwidth import config_ceiling

                info["omega0_ceiling"] = config_ceiling(cfg, u_scale=u_scale).to_dict()
            if cfg.sampling is not None and r_op is None:  # the loop as it runs, labelled
                from aiofl.analysis.sampled_loop import sampled_margins

                info["margins_of"] = "the continuous loop (no sampling)"
                info["sampled_loop"] = sampled_margins(cfg)
            extra_lines = _loop_extras(
                cfg,
                lin,
                info,
                two_dof,
                want_view and r_op is None,
                lag,
                measurement_delay,
                noise_std,
            )
            note = warnings_note(caught)
            if note is not None:
                info["numerical_warnings"] = note
            if figure is not None:
                from aiofl.analysis.frequency import loop_figure_bytes
                from aiofl.outputs import atomic_write_bytes

                title = (
                    f"{cfg.name}: loop broken at the plant input, linearised at r = {lin.r_op:g}"
                )
                if lin.notes and any("secant" in n for n in lin.notes):
                    title += f" (secant gains at ε = {amplitude:g})"
                data = loop_figure_bytes(
                    lin.loop_transfer(), lin.margins, title, figure.suffix.lower().lstrip(".")
                )
                atomic_write_bytes(figure, data)
            if as_json:
                typer.echo(json.dumps(info, indent=2))
            else:  # the config's name is user text: escaped for the terminal (aiofl.text)
                console.print(
                    terminal_text(format_linearization_text(lin, cfg.name, info), lines=True)
                )
                if extra_lines:
                    console.print(terminal_text("\n".join(extra_lines), lines=True))
                if "orbit" in info:
                    from aiofl.analysis.orbit import format_orbit_text

                    console.print(terminal_text(format_orbit_text(info["orbit"]), lines=True))
                if note is not None:
                    typer.echo(f"aiofl: note: {note}", err=True)
            if not as_json:
                _print_ceiling(target, u_scale, as_json=False, alone=False)
            return
        if r_op is not None:
            raise ValueError("--r-op applies only with --closed-loop")
        from aiofl.analysis.plant_structure import (
            analysis_to_dict,
            format_analysis_latex,
            format_analysis_text,
        )
        from aiofl.plants.plant_file import config_initial_state, load_symbolic_plant

        symbolic = load_symbolic_plant(target)
        analysis = symbolic.analyze()
        x0 = config_initial_state(target)  # a run config: β where `aiofl robustness` takes it
        if x0 is not None and len(x0) in (0, symbolic.n):
            label = "x0, the config's initial state" + ("" if x0 else " (zero)")
            analysis = analysis.at_point(x0 or (0.0,) * symbolic.n, label)
        if as_json:
            typer.echo(json.dumps(analysis_to_dict(analysis), indent=2))
        elif latex:  # names, description and units are user text: escaped (aiofl.text)
            typer.echo(terminal_text(format_analysis_latex(analysis), lines=True))
        else:
            console.print(terminal_text(format_analysis_text(analysis), lines=True))


def _loop_extras(
    cfg: Any,
    lin: Any,
    info: dict[str, Any],
    two_dof: bool,
    view: bool,
    lag: float,
    delay_samples: int,
    noise_std: float | None,
) -> list[str]:
    """The disk margin of the continuous loop (always), the loop-view rows and the 2-DOF
    form (when asked) into ``info``; returns their text lines."""
    from aiofl.analysis.loop_view import (
        continuous_disk_margin,
        format_loop_view_text,
        loop_view,
    )

    lines: list[str] = []
    disk = continuous_disk_margin(lin)
    info.update(disk)
    if disk["disk_margin"] is not None:  # a margin without bound (α ≥ 2: gain) is None
        alpha, gain, phase = (
            "∞" if v is None else f"{v:.4g}"
            for v in (
                disk["disk_margin"],
                disk["disk_gain_margin_db"],
                disk["disk_phase_margin_deg"],
            )
        )
        lines.append(
            f"  disk margin (continuous loop, skew 0): α = {alpha}, gain "
            f"×/÷ {gain} dB and phase ± {phase}° at once"
        )
    if view:
        v = loop_view(
            cfg, lag=lag, delay_samples=delay_samples, noise_std=noise_std, linearization=lin
        )
        info["loop_view"] = v
        u_unit = f"{cfg.plant.input_unit} " if cfg.plant.input_unit else ""
        lines += format_loop_view_text(v, cfg.plant.output_unit or "", u_unit)
    if two_dof:
        from aiofl.analysis.two_dof import format_two_dof_text, ladrc_two_dof

        try:
            forms = [ladrc_two_dof(cfg.controller)]
            if cfg.sampling is not None:
                forms.append(ladrc_two_dof(cfg.controller, cfg.sampling))
        except ValueError as exc:
            info["two_dof"] = {"reason": str(exc)}
            lines.append(f"2-DOF form: not available: {exc}")
        else:
            info["two_dof"] = [_form_dict(f) for f in forms]
            lines += format_two_dof_text(forms)
    return lines


def _form_dict(form: Any) -> dict[str, Any]:
    """JSON of a :class:`aiofl.analysis.two_dof.TwoDof`: polynomial coefficients."""

    def poly(tf: Any) -> dict[str, list[float]]:
        return {
            "num": [float(v) for v in tf.num[0][0]],
            "den": [float(v) for v in tf.den[0][0]],
        }

    nr = len(form.reference_inputs)
    return {
        "label": form.label,
        "dt": form.dt,
        "C": poly(form.feedback),
        "F": {
            name: poly(form.prefilter if nr == 1 else form.prefilter[0, j])
            for j, name in enumerate(form.reference_inputs)
        },
    }


def _print_ceiling(target: str, u_scale: float | None, *, as_json: bool, alone: bool) -> None:
    """Print the observer bandwidth ceiling of a run config (text or JSON); with
    ``alone`` the config is loaded here (bad input: exit 2)."""
    import json

    from aiofl.analysis.observer_bandwidth import config_ceiling
    from aiofl.cli.bad_input import bad_input_exits
    from aiofl.cli.configs import load_run_config
    from aiofl.text import terminal_text

    with bad_input_exits():
        if u_scale is not None and not (math.isfinite(u_scale) and u_scale > 0):
            raise ValueError(f"--u-scale = {u_scale}; allowed: a finite number > 0")
        cfg = load_run_config(target)
        result = config_ceiling(cfg, u_scale=u_scale)
    if as_json:
        typer.echo(json.dumps(result.to_dict(), indent=2))
        return
    text = result.format_text(cfg.controller.value("eso.omega0"))
    typer.echo(terminal_text(("" if alone else "\n") + text, lines=True))


def _check_budget_option(budget: float) -> None:
    if not (math.isfinite(budget) and budget > 0):
        raise ValueError(f"--budget = {budget}; allowed: a finite number of seconds > 0")


def _check_figure_path(figure: Path, closed_loop: bool, *, force: bool) -> None:
    """Refuse a ``--figure`` that cannot be written, before any work is done: an existing
    file without ``--force`` too (:func:`aiofl.outputs.check_file_replaceable`)."""
    from aiofl.analysis.frequency import FIGURE_FORMATS
    from aiofl.outputs import check_file_replaceable

    if not closed_loop:
        raise ValueError("--figure applies only with --closed-loop")
    suffix = figure.suffix.lower().lstrip(".")
    if suffix not in FIGURE_FORMATS:
        raise ValueError(
            f"--figure {str(figure)!r}: file type {suffix or '(none)'!r}; allowed: "
            + ", ".join(f".{f}" for f in FIGURE_FORMATS)
        )
    check_file_replaceable(figure, force=force, option="--figure")
