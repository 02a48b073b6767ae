r"""A slow, independent reference path for the *sampled* loop: the plant by scipy
``solve_ivp`` between events, the controller stepped sample by sample.

The sampled counterpart of :mod:`aiofl.engine.reference` (whose loop, written from the
paper's equations, it shares nothing with but the reference's derivatives): everything
around the controller is written here independently of the engine's time loop, event by
event: the ADC reading the plant's output (with a sensor delay) plus the held noise, the
controller's update, the DAC holding the command (with a computation or an actuator delay),
the disturbance and the parameter change.  The controller is the engine's discrete update,
compiled without a plant (:mod:`aiofl.engine.build.controller_update`), whose numbers the tests
check separately.  Slow; for cross-checks in tests only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.integrate import solve_ivp

from aiofl.controller import Controller, controller_batch
from aiofl.engine.build.controller_update import NO_TABLE, compiled_update, member_constants
from aiofl.engine.kernel.sampled import N_CS
from aiofl.engine.observer_gains import model_jacobians
from aiofl.engine.reference import _reference_derivatives
from aiofl.engine.sample_time import discrete_row
from aiofl.layout import RHO_MAX
from aiofl.plants.base import Plant
from aiofl.scenario import Scenario, noise_sequence

__all__ = ["SampledReferenceResult", "reference_sampled_simulate"]


@dataclass(frozen=True)
class SampledReferenceResult:
    """Output of :func:`reference_sampled_simulate`, one row per sample :math:`t_k = kT_s`.

    Attributes
    ----------
    t
        The sample times.
    x
        The plant state at :math:`t_k`.
    y_meas
        What the ADC read at :math:`t_k`: :math:`y(t_k - \\tau_{out}) + n(t_k)`, quantised.
    u
        The command the plant sees on :math:`[t_k, t_k + dt)`: the DAC's, delayed by
        :math:`\\tau_{in}`.
    """

    t: NDArray[np.float64]
    x: NDArray[np.float64]
    y_meas: NDArray[np.float64]
    u: NDArray[np.float64]


def reference_sampled_simulate(
    plant: Plant,
    controller: Controller,
    scenario: Scenario,
    sampling: object,
    *,
    rtol: float = 1e-10,
    atol: float = 1e-12,
) -> SampledReferenceResult:
    r"""The sampled loop with its transport delays, event by event (slow; for cross-checks).

    The controller is the engine's discrete update stepped from Python as compiled without
    a plant (:mod:`aiofl.engine.build.controller_update`, the update
    :class:`aiofl.discrete_controller.DiscreteController` steps, which the tests check
    separately); everything around it is written here independently of the time loop: the
    plant integrated by ``solve_ivp`` between events, the ADC reading
    :math:`y(\max(t_k - \tau_{out}, 0))` plus the noise held at :math:`t_k`, the DAC
    holding :math:`u_k` (or :math:`u_{k-1}` with the one-sample computation delay) from
    :math:`t_k + \tau_{in}` (0 before :math:`\tau_{in}`), the disturbance and the
    parameter change.  Events at one time are taken in the order: measurement, controller
    update, command change.

    Parameters
    ----------
    plant, controller, scenario, sampling
        The loop and its sampling.
    rtol, atol
        The tolerances of ``solve_ivp``.

    Returns
    -------
    SampledReferenceResult
    """
    sc = scenario
    ts = float(sampling.ts)  # type: ignore[attr-defined]
    t_end = float(sc.t_final)
    n_samp = round(t_end / ts)
    tin, tout = float(sc.input_delay), float(sc.output_delay)
    model = controller.eso_model != "none"
    # the controller's update, its constants, coefficient row and state (as
    # DiscreteController packs them; a model-assisted observer's gain placed at Φ(x0))
    update = compiled_update(plant if model else None)
    q, iq = member_constants(update, controller)
    jac = model_jacobians(plant, controller_batch(controller), [sc.x0]) if model else None
    row = discrete_row(controller, sampling, jac)  # type: ignore[arg-type]
    cs, scr = np.zeros(N_CS), np.zeros(N_CS)
    rr = np.zeros((1, RHO_MAX + 2))
    pn = plant.param_vector() if model else np.zeros(1)
    noise = (
        np.sqrt(sc.noise_variance) * noise_sequence(sc.noise_seed, sc.noise_samples)
        if sc.noise_variance > 0
        else None
    )
    p_nom = plant.param_vector()
    p_chg = plant.param_vector(sc.plant_overrides, sc.plant_scale)
    yq = float(getattr(sampling, "y_quantum", 0.0))
    uq = float(getattr(sampling, "u_quantum", 0.0))
    comp_delay = bool(getattr(sampling, "delay", 0))
    n_deriv = controller.rho + 1 if controller.td == "exact" else 1

    def rnd(v: float, q: float) -> float:
        return q * float(np.floor(v / q + 0.5)) if q > 0.0 else v

    # events (time, kind 0 measure / 1 update / 2 command, sample index); a time within
    # 1e-12 s of another is the same instant
    events = []
    for k in range(n_samp):
        events.append((round(max(k * ts - tout, 0.0), 12), 0, k))
        events.append((round(k * ts, 12), 1, k))
        events.append((round(k * ts + tin, 12), 2, k))
    for tb in (sc.disturbance_time, sc.parameter_change_time):
        events.append((round(tb, 12), 3, -1))
    events.sort()
    x = np.zeros(plant.n_states) if not sc.x0 else np.asarray(sc.x0, dtype=float)
    t_now = 0.0
    u_applied = 0.0
    y_read = np.zeros(n_samp)
    u_cmd = np.zeros(n_samp)
    xs = np.zeros((n_samp, plant.n_states))
    us = np.zeros(n_samp)

    def inputs(t: float) -> tuple[float, NDArray[np.float64]]:
        d = sc.disturbance_amplitude if t >= sc.disturbance_time * (1 - 1e-12) else 0.0
        p = p_chg if t >= sc.parameter_change_time * (1 - 1e-12) else p_nom
        return d, p

    for te, kind, k in events:
        if te > t_end:
            break
        if te > t_now:  # integrate the plant to the event under the held inputs
            d, p = inputs(t_now)
            sol = solve_ivp(
                lambda _t, xx, u=u_applied, d=d, p=p: plant.rhs(xx, u, d, p),
                (t_now, te),
                x,
                method="DOP853",
                rtol=rtol,
                atol=atol,
            )
            if not sol.success:
                raise RuntimeError(f"solve_ivp failed on [{t_now}, {te}]: {sol.message}")
            x, t_now = sol.y[:, -1].copy(), te
        if kind == 0:
            y_read[k] = plant.output(x, inputs(t_now)[1])
        elif kind == 1:
            tk = k * ts
            n_k = 0.0 if noise is None else float(noise[int(tk / sc.noise_hold + 1e-9)])
            ym = rnd(y_read[k] + n_k, yq)
            y_read[k] = ym
            if k == 0:
                update.init(iq, q, cs, float(ym))
            rd = _reference_derivatives(sc, tk, n_deriv, tk >= sc.reference.t_step)
            rr[0, :] = 0.0
            rr[0, : len(rd)] = rd
            u_cmd[k] = float(update.step(NO_TABLE, iq, q, row, cs, scr, float(ym), rr, 0, pn))
            xs[k] = x
        elif kind == 2:
            u_applied = rnd(u_cmd[k - 1] if comp_delay and k > 0 else 0.0, uq)
            if not comp_delay:
                u_applied = rnd(u_cmd[k], uq)
    # the command the plant sees at each sample instant (after that instant's events)
    for k in range(n_samp):
        j = int(np.floor((k * ts - tin) / ts + 1e-9))  # the last DAC update at or before
        if j < 0:
            us[k] = 0.0
        elif comp_delay:
            us[k] = rnd(u_cmd[j - 1], uq) if j > 0 else 0.0
        else:
            us[k] = rnd(u_cmd[j], uq)
    return SampledReferenceResult(t=np.arange(n_samp) * ts, x=xs, y_meas=y_read, u=us)
