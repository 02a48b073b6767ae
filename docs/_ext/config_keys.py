"""What each key of a run config means: the words of the configuration reference.

Types, ranges and defaults are read from the pydantic models when the docs build
(:mod:`config_reference`); only the meanings are written here.  A key of the schema missing
here, or a key here the schema does not have, stops the build and fails
``tests/test_docs_config_reference.py``.
"""

from __future__ import annotations

#: one sentence or two per table (``""`` the top level; ``NAME`` a key the user chooses)
TABLE_MEANINGS: dict[str, str] = {
    "": "The keys outside any table.  A config must set at least ``plant``, "
    "``[scenario] t_final``, ``[controller] structure`` and ``[simulation] dt``, so an empty "
    "or cut-off file is refused rather than run with defaults.",
    "scenario": "The test: horizon, reference, disturbance, changes to the true plant, "
    "output noise, initial state, transport delays (:class:`aiofl.scenario.Scenario`).",
    "scenario.reference": "The reference r(t) (:class:`aiofl.scenario.Reference`): "
    "``sine`` r = A sin(ωt + φ) + r0, ``step`` r = r0 + A·1(t ≥ t_step), ``samples`` a "
    "linear interpolation of ``samples`` spaced ``sample_dt`` apart (held at the last "
    "value).  Left out: the paper's (π/4)·sin 2t, printed by ``aiofl simulate --check``.",
    "controller": "The controller (:class:`aiofl.controller.Controller`): a ``structure`` "
    "(or the component kinds one by one), its order and the parameter tables of its parts.  "
    "A parameter the chosen kinds use that has no sensible default must be given; a missing "
    "one is refused naming it.",
    "controller.eso": "The extended state observer of order ρ+1 (eqs. 5, 16, 19).",
    "controller.td": "The tracking differentiator: Han's TD (eq. 18), the improved TD "
    '(eq. 21) or the linear prefilter; ``td_kind = "exact"`` uses the reference\'s exact '
    "derivatives and reads nothing here.",
    "controller.sef": "The state error feedback: NLSEF with fal (eq. 17), INLSEF (eq. 20) or "
    "linear full-state feedback with every pole at −ω_c.  A vector needs one entry per "
    "fed-back state (at least ``n_feedback``); a short one is refused, not padded.",
    "controller.law": "The control law u = v − ξ̂_{ρ+1}/b0 (eq. 14) and the actuator range.",
    "controller.discrete": "Run the controller sampled, as a processor does "
    "(:mod:`aiofl.engine.discrete_rows`): at t_k = k·ts it reads y, updates once and holds its "
    "command until the next sample.  Prefer ``[sensor]`` for ``ts`` and the quantum.",
    "simulation": "The integrator of the closed loop.",
    "metrics": "The OPI of eq. (22): OPI = Σ w_i·J_i/N_i over ITAE, ISU and IAU.",
    "tune": "The search of ``aiofl tune`` (:class:`aiofl.tuning.space.TuneSettings`); "
    "validated by every command that reads the config, exactly as ``aiofl tune`` does.",
    "tune.parameters.NAME": "One searched parameter, keyed by its engine column name "
    '(``"eso.omega0"``, ``"sef.omega_c"``, ``"td.omega"``, ``"law.b0"``, ...; '
    ":data:`aiofl.layout.FLOAT_COLUMNS`).  A parameter the structure does not use, bounds "
    "outside the schema's range for that field or reversed bounds are refused.",
    "tune.robust": "Robust tuning: every candidate is scored on the nominal plant and the "
    "same ``draws`` plants of ``[uncertainty]`` (common random numbers); a candidate with "
    "any diverged member is infeasible.",
    "uncertainty": "The model error as data (:class:`aiofl.uncertainty.UncertaintyModel`): "
    "draws of the *true* plant's parameters (the controller is not told), and optionally of "
    "the sample time, the noise variance and the delays.  Read by ``aiofl robustness``, "
    "robust tuning and the report.",
    "uncertainty.parameters.NAME": "One plant parameter's factor on its nominal value "
    "(:class:`aiofl.uncertainty.Distribution`), keyed by the plant's parameter name; set "
    "exactly one of ``uniform``, ``normal``, ``log_uniform``.  An unknown name is refused "
    "naming the plant's parameters.",
    "sensor": "The measurement as a user has it (:class:`aiofl.sensor.Sensor`): a preset and "
    "keys that override its values.  It fills ``[scenario]``'s noise and "
    "``[controller.discrete]``'s ``ts`` / ``y_quantum``; a quantity set here and in its "
    "old place is refused, naming both (except an equal ``[controller.discrete] ts``).",
    "rig": "What a real loop adds to the plant and the controller is not told "
    "(:class:`aiofl.rig.Rig`): delays, an actuator, friction at the plant's input and the "
    "sensor the rig pairs with.  Explicit keys override the preset's values.",
}

#: the meaning of every key, by dotted path
KEY_MEANINGS: dict[str, str] = {
    # ------------------------------------------------------------------ top level
    "name": "The config's label (metrics.json's ``name``); plain text, at most 200 "
    "characters, no control or bidirectional characters.",
    "description": "Free text (at most 2,000 characters); it reaches exported C only "
    "through the comment filter.",
    "plant": "A registered plant's name (``slfjm``, ``pendulum``, ``tank``, "
    "``dcmotor_arm``, ``flexjoint_hub``, or one registered with "
    ":func:`aiofl.plants.register_plant`) or a plant file ``*.toml``, relative to the "
    "config.",
    "scenario": "The scenario table.",
    "controller": "The controller table.",
    "simulation": "The integrator table.",
    "metrics": "The OPI weights table.",
    "tune": "The search of ``aiofl tune``; absent: the config cannot be tuned.",
    "uncertainty": "The model error; absent: ``aiofl robustness`` and robust tuning refuse "
    "the config.",
    "sensor": "The measurement; absent: what ``[scenario]`` and ``[controller.discrete]`` "
    "say (the ideal sensor by default).",
    "rig": "The rig; absent: the bare plant.",
    # ------------------------------------------------------------------ scenario
    "scenario.name": "The scenario's label (metrics.json's ``scenario_name``).",
    "scenario.reference": "The reference table.",
    "scenario.t_final": "Horizon [s]; a whole number of steps ``dt`` (within 1e-9, never "
    "rounded silently), at most 2e7 steps per member.",
    "scenario.disturbance_amplitude": "Step input disturbance τ_d through the plant's b_d "
    "(N·m for the SLFJM), from ``disturbance_time``.",
    "scenario.disturbance_time": "When the disturbance steps in [s]; at most ``t_final``.",
    "scenario.plant_scale": "Factors on the *true* plant's parameters (``{ J_l = 1.4 }``), "
    "from ``parameter_change_time``; the controller's nominal model is not changed.",
    "scenario.plant_overrides": "Values replacing the true plant's parameters, from "
    "``parameter_change_time``; the controller is not told.",
    "scenario.parameter_change_time": "When ``plant_scale`` / ``plant_overrides`` take "
    "effect [s]; at most ``t_final``.",
    "scenario.noise_variance": "Variance of the Gaussian output noise the controller reads "
    "(the metrics use the true output).",
    "scenario.noise_hold": "The noise is held constant over this time [s].",
    "scenario.noise_seed": "Seed of the noise sequence (same seed, same numbers).",
    "scenario.x0": "Initial plant state, one entry per state; empty: zeros.",
    "scenario.input_delay": "Transport delay of the command [s]: the plant sees u(t − τ) "
    "(0 before). A multiple of ``dt``, shorter than the horizon.",
    "scenario.output_delay": "Transport delay of the measurement [s]: the controller reads "
    "y(t − τ) (y(0) before). A multiple of ``dt``, shorter than the horizon.",
    "scenario.envelope": "The operating envelope: a run whose |y − r| exceeds it is *lost* "
    "(stopped, reported with its time).  Not set: ten times the scenario's output scale, the "
    "largest of |r(t)| and |y(0)| (none when that is 0); ``inf`` switches it off.",
    "scenario.u_ref": 'ISU and IAU measure u − u_ref; ``"trim"``: the holding input at the '
    "reference's first value (``aiofl trim``), so holding the plant costs nothing.",
    "scenario.steady_from": "Start of the steady-state window [s] (steady error, u's noise); "
    "not set: the last 20 % of the horizon.",
    # ------------------------------------------------------------ scenario.reference
    "scenario.reference.kind": "The shape of r(t).",
    "scenario.reference.amplitude": "A, the sine's amplitude or the step's height; the "
    "default is π/4 (45°), the paper's.",
    "scenario.reference.omega": "ω of the sine [rad/s].",
    "scenario.reference.phase": "φ of the sine [rad].",
    "scenario.reference.offset": "r0, added to every kind.",
    "scenario.reference.t_step": "When the step happens [s]; at most ``t_final``.",
    "scenario.reference.samples": "The values of a ``samples`` reference (at least 2).",
    "scenario.reference.sample_dt": "Spacing of ``samples`` [s]; > 0 for a ``samples`` reference.",
    # ------------------------------------------------------------------ controller
    "controller.structure": "LESO (linear ESO + NLSEF + Han's TD), INLESO (improved ESO + "
    "INLSEF + ITD), LADRC (linear ESO + linear prefilter + linear full-state feedback) or "
    "IOFL (classical model-based IOFL); required in every config.",
    "controller.eso_kind": "Override the structure's observer: ``linear`` (eqs. 5, 16) or "
    "``improved`` (eq. 19).",
    "controller.td_kind": "Override the structure's differentiator: ``exact`` (the "
    "reference's exact derivatives), ``han`` (eq. 18), ``improved`` (eq. 21), ``linear`` "
    "(prefilter of order ρ).",
    "controller.sef_kind": "Override the structure's feedback: ``nonlinear`` (eq. 17), "
    "``improved`` (eq. 20), ``linear`` (poles at −ω_c).",
    "controller.law_kind": "Override the law: ``aiofl`` (eq. 14) or ``iofl`` (model-based).",
    "controller.rho": "The controller's relative degree; not set: the plant's.  Another "
    "value is refused unless ``allow_rho_mismatch = true``.",
    "controller.n_feedback": "How many estimated states the SEF feeds back; not set: ρ "
    "(full state feedback), or the paper's 2 behind Han's TD or the ITD (which supply only "
    "r and r').",
    "controller.allow_rho_mismatch": "Run a ρ other than the plant's relative degree.",
    "controller.allow_b0_sign_mismatch": "Run a b0 whose sign differs from the plant's "
    "high-frequency gain β = L_gL_f^{ρ−1}h at the initial state.",
    "controller.eso": "The observer table.",
    "controller.td": "The differentiator table.",
    "controller.sef": "The feedback table.",
    "controller.law": "The law table.",
    "controller.discrete": "Run sampled; absent: a continuous controller (unless "
    "``[sensor]`` gives a sample time).",
    # ------------------------------------------------------------------ eso
    "controller.eso.omega0": "Observer bandwidth ω0 [rad/s]: gains β_i = α_i ω0^i.  "
    "Required by the linear and the improved ESO with bandwidth gains.",
    "controller.eso.alpha": 'The ratios α_1..α_{ρ+1} (ρ+1 entries); ``"binomial"``: Gao\'s '
    "α_i = C(ρ+1, i), every observer pole at −ω0.",
    "controller.eso.k_alpha": "INLESO injection gain k_α of φ(e) = k_α|e|^a sign(e) + "
    "k_β|e|^b e (eq. 19).",
    "controller.eso.k_beta": "INLESO injection gain k_β (eq. 19).",
    "controller.eso.g_alpha": "INLESO exponent a of eq. (19).",
    "controller.eso.g_beta": "INLESO exponent b of eq. (19).",
    "controller.eso.init": 'How the observer starts: ``"zero"`` ξ̂(0) = 0; '
    '``"output"`` ξ̂_1(0) = the first measurement y_meas(0); ``"bumpless"`` that, and '
    "the differentiator / prefilter at rest at y_meas(0), so a plant at rest at y0 = r gets "
    "u = 0 (or ``u0``) at the first sample instead of a command step.  The exported C "
    "starts bumpless by default.",
    "controller.eso.u0": 'The command held at the start (with ``init = "output"`` or '
    '``"bumpless"``): the extended state starts at ξ̂_{ρ+1} = −b0·u0, so u(t0) = u0 '
    '(bumpless transfer); ``"trim"``: the holding input at the initial output.',
    "controller.eso.delay": "A known measurement delay [s], a whole number (at most 8) of the "
    "sampled controller's ts: the ESO is fed the command that many samples older and the "
    'reference is delayed as much (aligned with the measurement); ``"rig"``: the '
    "``[rig]``'s ``measurement_delay``.",
    "controller.eso.model": '``"none"``: model-free (eq. 5); ``"nominal"``: '
    "model-assisted, the observer's ρ-th equation carries the plant's nominal α0(x̂) + "
    "β0(x̂)u at x̂ = Φ⁻¹(ξ̂), so ξ̂_{ρ+1} estimates only what the model misses.",
    "controller.eso.gains": '``"bandwidth"``: β_i = α_i ω0^i; ``"kalman"``: the '
    "steady-state Kalman gains from ``q`` and ``r`` (:mod:`aiofl.components.kalman`); "
    "``omega0`` and ``alpha`` are then derived and may not be given.",
    "controller.eso.q": "Kalman gains: process-noise intensity on the extended state's "
    'derivative (required with ``gains = "kalman"``; tunable as ``"eso.q"``).',
    "controller.eso.r": "Kalman gains: measurement-noise intensity; not set: from the run's "
    "sensor, noise_variance·noise_hold (continuous) or noise_variance·max(noise_hold, ts) + "
    "y_quantum²/12·ts (sampled).",
    # ------------------------------------------------------------------ td
    "controller.td.R": "Han's TD acceleration bound R (eq. 18); required by ``han``.",
    "controller.td.a": "ITD constant a (eq. 21); r1 → (1 − a) r / b, so a = 1 − b tracks r.",
    "controller.td.b": "ITD constant b (eq. 21).",
    "controller.td.c": "ITD constant c (eq. 21).",
    "controller.td.rho": "ITD constant ϱ (eq. 21).",
    "controller.td.omega": "Bandwidth ω_r of the linear prefilter ω_r^ρ/(s + ω_r)^ρ "
    "[rad/s]; required by ``linear``.",
    # ------------------------------------------------------------------ sef
    "controller.sef.k": "NLSEF gains k_i (default 1 each, the paper's), or INLSEF k_{i1}.",
    "controller.sef.kb": "INLSEF gains k_{i2} (eq. 20).",
    "controller.sef.alpha": "fal exponents α_i (NLSEF, eq. 17) or INLSEF exponents.",
    "controller.sef.delta": "fal linear-zone widths δ_i (eq. 17).",
    "controller.sef.mu": "INLSEF μ_i (eq. 20).",
    "controller.sef.v_limit": "INLSEF output bound δ of δ·tanh(·/δ) (eq. 20).",
    "controller.sef.omega_c": "Controller bandwidth ω_c [rad/s] of the linear SEF: every "
    "tracking-error pole at −ω_c; required by ``linear``.",
    # ------------------------------------------------------------------ law
    "controller.law.b0": "The input gain the law divides by; finite and non-zero, negative "
    "for a plant whose β is negative; required.  Its sign must match β at the initial "
    "state unless ``allow_b0_sign_mismatch``.",
    "controller.law.u_max": "Actuator upper limit; ``u_max`` alone gives [−u_max, u_max]; "
    "``inf``: no limit.",
    "controller.law.u_min": "Actuator lower limit (u_min < u_max).",
    # ------------------------------------------------------------------ discrete
    "controller.discrete.ts": "Sample time [s], an integer multiple of ``dt``, at least 10 "
    "samples over the horizon.",
    "controller.discrete.delay": "1: the command computed at t_k is applied at t_{k+1} "
    "(the integer 0 or 1; ``true`` is refused).",
    "controller.discrete.y_quantum": "ADC quantum of y (0: none); prefer ``[sensor] quantum``.",
    "controller.discrete.u_quantum": "DAC quantum of u (0: none).",
    "controller.discrete.eso": 'Linear ESO discretisation: ``"zoh"`` (exact ZOH, current '
    'observer; the default) or ``"euler"``; the INLESO is always forward Euler.',
    "controller.discrete.td": "Han's TD discretisation: ``\"fhan\"`` (Han's discrete TD) or "
    '``"euler"`` (forward Euler on eq. 18).',
    "controller.discrete.h0": "fhan's filter factor; not set: ts; 1e-3·ts ≤ h0 ≤ 100·ts.",
    # ------------------------------------------------------------------ simulation
    "simulation.dt": "Integration step [s]; required in every config.",
    "simulation.method": "Fixed-step RK4 or forward Euler.",
    "simulation.decimation": "Store every N-th step of the trajectory (the stored "
    "trajectory is bounded at 512 MiB).",
    "simulation.divergence_threshold": "A plant state beyond it (or non-finite) stops the "
    "run as *diverged*, with its time; the default is 1e10.  Finite: an infinite "
    "threshold would switch detection off.",
    # ------------------------------------------------------------------ metrics
    "metrics.weights": "OPI weights (w1, w2, w3) of ITAE, ISU, IAU; the paper prints "
    "(0.6, 0.2, 0.6), which sum to 1.4: kept as printed.",
    "metrics.normalisers": "OPI normalisers (N1, N2, N3) of ITAE, ISU, IAU.",
    # ------------------------------------------------------------------ tune
    "tune.algorithm": "pymoo's GA, DE, CMA-ES, or NSGA-II (multi-objective).",
    "tune.objective": 'Single-objective: ``"opi"`` (the config\'s ``[metrics]``), a metric '
    "(``itae iae ise isu iau``) or a weighted sum such as ``{ itae = 1.0, isu = 0.1 }``.",
    "tune.t_final": "Tuning horizon [s], at most the scenario's; not set: the scenario's.",
    "tune.population": "Members per generation (one batched engine call).",
    "tune.generations": "Generations; population × generations ≤ 1e6 evaluations.",
    "tune.seed": "The search's seed: the same seed gives the same result bit for bit.",
    "tune.divergence_penalty": "P: a member that diverges at t_d scores P·(2 − t_d/t_f).",
    "tune.include_initial": "The config's own values are member 0 of the first generation.",
    "tune.dt": "Integration step for tuning; not set: ``[simulation] dt``.",
    "tune.method": "Integrator for tuning; not set: ``[simulation] method``.",
    "tune.chunks": "Dask chunks per generation; not set: one per worker.",
    "tune.parameters": "The searched parameters (at least one).",
    "tune.robust": "Robust tuning over ``[uncertainty]`` draws; not set: the nominal plant.",
    "tune.noise_realisations": "With a noisy measurement, score every candidate over this "
    "many noise sequences (common random numbers), the mean cost.",
    "tune.objectives": "NSGA-II: 2 or 3 quantities, minimised (``METRIC`` or "
    "``METRIC:AGGREGATE``; margins ``pm gm dm`` are maximised, ``ms`` minimised).",
    "tune.constraints": "NSGA-II: ``QUANTITY <= NUMBER`` or ``QUANTITY >= NUMBER`` "
    '(e.g. ``"isu <= 15.5"``, ``"stable_fraction >= 1"``, ``"pm >= 45"``).',
    "tune.choose": "Which front design becomes best.toml: the lowest first objective, or "
    "the knee (nearest the ideal point).",
    "tune.omega0_ceiling": 'Clip ``"eso.omega0"``\'s ``hi`` to ``aiofl analyze '
    "--ceiling``'s ceiling.",
    "tune.parameters.NAME.lo": "Lower bound.",
    "tune.parameters.NAME.hi": "Upper bound (> lo).",
    "tune.parameters.NAME.log": "Search in log scale (needs lo > 0).",
    "tune.robust.draws": "K perturbed plants per candidate; population × (K + 1) ≤ 10,000.",
    "tune.robust.aggregate": "How the K + 1 values combine: mean, worst (max) or CVaR_α "
    "(the mean of the worst ⌈(1 − α)(K + 1)⌉).",
    "tune.robust.alpha": "α of CVaR.",
    "tune.robust.corners": "Also score the 2^k corners of the ``[uncertainty]`` box "
    "(recommended for new recipes; false so the shipped presets reproduce).",
    # ------------------------------------------------------------------ uncertainty
    "uncertainty.draws": "How many plants to draw.  The first n of N draws are the draws of "
    "``draws = n``.",
    "uncertainty.seed": "The draws depend only on the seed, the table and ``draws``, never "
    "on the controller (paired comparisons).",
    "uncertainty.parameters": "Factors on the plant's nominal parameters, from t = 0 "
    "(multiplying the scenario's own ``plant_scale``).",
    "uncertainty.ts": "Sample-time range [a, b] (drawn among the multiples of ``dt``); needs "
    "a sampled controller; 0 < a ≤ b ≤ 1 s.",
    "uncertainty.noise_variance": "Output-noise variance range [a, b]; a drawn variance "
    "replaces the sensor's.",
    "uncertainty.output_delay": "Measurement-delay range [a, b] [s] (multiples of ``dt``).",
    "uncertainty.input_delay": "Command-delay range [a, b] [s] (multiples of ``dt``).",
    "uncertainty.parameters.NAME.uniform": "p: f ~ U[1 − p, 1 + p].",
    "uncertainty.parameters.NAME.normal": "σ: f = 1 + σz, z standard normal truncated to "
    "|z| < 1/σ (0 < f < 2).",
    "uncertainty.parameters.NAME.log_uniform": "[a, b]: ln f ~ U[ln a, ln b], 0 < a < b.",
    # ------------------------------------------------------------------ sensor
    "sensor.preset": "The sensor preset: ``ideal`` (continuous, unquantised, noise-free), "
    "``encoder-12bit`` / ``-14bit`` / ``-16bit`` (Ts = 1 ms, quantum 2π/2^N rad).",
    "sensor.ts": "Sample time [s]: the controller runs sampled at ts (dt ≤ ts, a multiple of dt).",
    "sensor.quantum": "Measurement quantum (an encoder of N counts per revolution: 2π/N "
    "rad); needs a sample time.",
    "sensor.noise_variance": "Gaussian output-noise variance.",
    "sensor.noise_hold": "The noise is held over this time [s]; not set: ts.",
    "sensor.noise_seed": "Seed of the noise.",
    # ------------------------------------------------------------------ rig
    "rig.preset": "``ideal`` (nothing added) or ``servo-1khz``: the 12-bit encoder at 1 ms, "
    "1 ms of measurement delay, a 1 ms actuator lag and Coulomb friction of 0.01 input "
    "units.",
    "rig.sensor": "The ``[sensor]`` preset the rig pairs with.",
    "rig.measurement_delay": "[s] → ``[scenario] output_delay`` (the ADC reads y(t − τ)).",
    "rig.computation_delay": "[s] → ``[scenario] input_delay`` (the plant gets u(t − τ)).",
    "rig.lag": "First-order actuator τ_a [s]: τ_a du_a/dt = u − u_a.",
    "rig.lag2": "Second-order actuator [ω_n rad/s, ζ], instead of ``lag``.",
    "rig.rate_limit": "|du_a/dt| ≤ R (needs an actuator lag).",
    "rig.rate_filter": "The rate limiter's filter τ_w [s]; not set: τ_a/10.",
    "rig.coulomb": "Coulomb friction F_c at the plant's input: u_eff = u_a − F_c tanh(v/ε) − "
    "b_v v (input units).",
    "rig.viscous": "Viscous friction b_v (input units per unit of ``friction_state``).",
    "rig.friction_state": "The plant's velocity state the friction acts on (required with "
    "friction).",
    "rig.smoothing": "ε of tanh(v/ε), in the units of ``friction_state``.",
}

#: the keys of a plant file (:class:`aiofl.plants.symbolic.SymbolicPlant`)
PLANT_FILE_KEYS: dict[str, str] = {
    "name": "The plant's name (required).",
    "description": "Free text (optional).",
    "states": 'The state names, a list, or a ``[states]`` table ``theta = "angle [rad]"``.',
    "params": "The ``[params]`` table: every parameter's nominal value.",
    "f": "The drift, one expression per state.",
    "g": "The input vector field, one expression per state.",
    "h": "The output, one expression.",
    "bd": "The disturbance input vector field (optional).",
    "eta": "Internal coordinates η where ρ < n (optional; found automatically when g has a "
    "constant direction).",
    "equilibrium": "The operating point x_e for the zero dynamics and β(x_e) (optional).",
    "output_unit": "Unit of y (plain text): figures, trajectory.csv's units line, reports.",
    "input_unit": "Unit of u.",
    "disturbance_unit": "Unit of τ_d.",
    "state_units": "Units of the states, one per state.",
    "bounds": "A ``[bounds]`` table: a state's physical ``[low, high]``; a run that leaves "
    "it is *lost*.",
    "output_range": "The output's physical ``[low, high]``; a run that leaves it is *lost*.",
}
