"""Flat numeric layout of one closed-loop member, shared by the host and the compiled engine.

The engine runs a *batch* of closed loops; member ``m`` is described by one row of an
integer array (component kinds, orders) and one row of a float array (every tunable
number).  Component kinds are data, not code paths chosen in Python, so one compiled
kernel serves every combination and a GA generation is a single call.

The column names are the public vocabulary for addressing parameters (the tuner, the
TOML configs and ``Controller.with_values`` all use them), e.g. ``"eso.omega0"``,
``"eso.alpha3"`` or ``"sef.delta1"``.  Vector parameters are numbered from 1, as in the
paper.
"""

from __future__ import annotations

from types import MappingProxyType

RHO_MAX = 8
"""Largest controller order ρ the engine supports (ESO order ρ+1 ≤ 9)."""

# ----------------------------------------------------------------------------- kinds
ESO_LINEAR = 0  #: linear ESO, eqs. (5)/(16)
ESO_IMPROVED = 1  #: improved nonlinear ESO (INLESO), eq. (19)
ESO_KINDS = MappingProxyType({"linear": ESO_LINEAR, "improved": ESO_IMPROVED})

TD_EXACT = 0  #: analytic reference derivatives (no differentiator)
TD_HAN = 1  #: Han's nonlinear TD, eq. (18) with the 2R correction
TD_IMPROVED = 2  #: improved TD (ITD), eq. (21)
TD_LINEAR = 3  #: linear prefilter of order ρ with poles at -ω_r
TD_KINDS = MappingProxyType(
    {"exact": TD_EXACT, "han": TD_HAN, "improved": TD_IMPROVED, "linear": TD_LINEAR}
)

SEF_NONLINEAR = 0  #: NLSEF with fal, eq. (17)
SEF_IMPROVED = 1  #: improved NLSEF (INLSEF), eq. (20)
SEF_LINEAR = 2  #: linear full-state feedback with poles at -ω_c
SEF_KINDS = MappingProxyType(
    {"nonlinear": SEF_NONLINEAR, "improved": SEF_IMPROVED, "linear": SEF_LINEAR}
)

ESO_INIT_ZERO = 0  #: ξ̂(0) = 0
ESO_INIT_OUTPUT = 1  #: ξ̂_1(0) = y_meas(0), the first measurement; ξ̂_2..ξ̂_{ρ+1}(0) = 0
#: ξ̂(0) = (y_meas(0), 0, ..., 0) and the differentiator / prefilter at rest at y_meas(0): a
#: plant at rest at y0 = r sees no command step (a bumpless start, the exported C's default)
ESO_INIT_BUMPLESS = 2
ESO_INIT_KINDS = MappingProxyType(
    {"zero": ESO_INIT_ZERO, "output": ESO_INIT_OUTPUT, "bumpless": ESO_INIT_BUMPLESS}
)

ESO_MODEL_NONE = 0  #: model-free: the ESO's ρ-th equation carries b0 u only, eq. (5)
ESO_MODEL_NOMINAL = 1  #: model-assisted: it carries the nominal α(x̂) + β(x̂) u, x̂ = Φ⁻¹(ξ̂)
ESO_MODEL_KINDS = MappingProxyType({"none": ESO_MODEL_NONE, "nominal": ESO_MODEL_NOMINAL})
ESO_GAINS_BANDWIDTH = 0  #: β_i = α_i ω0^i from the given ω0 and α (Gao's bandwidth form)
ESO_GAINS_KALMAN = 1  #: steady-state Kalman gains from eso.q, eso.r (components.kalman)
ESO_GAINS_KINDS = MappingProxyType({"bandwidth": ESO_GAINS_BANDWIDTH, "kalman": ESO_GAINS_KALMAN})

LAW_AIOFL = 0  #: u = v - ξ̂_{ρ+1}/b0, eq. (14)
LAW_IOFL = 1  #: classical model-based IOFL, u = (-α(x) + v)/β(x)
LAW_KINDS = MappingProxyType({"aiofl": LAW_AIOFL, "iofl": LAW_IOFL})

REF_SINE = 0  #: r = A sin(ω t + φ) + offset
REF_STEP = 1  #: r = offset + A·1(t ≥ t_step)
REF_SAMPLES = 2  #: user samples on a uniform grid, linear interpolation
REF_KINDS = MappingProxyType({"sine": REF_SINE, "step": REF_STEP, "samples": REF_SAMPLES})

METHOD_RK4 = 0
METHOD_EULER = 1
METHODS = MappingProxyType({"rk4": METHOD_RK4, "euler": METHOD_EULER})

# What a member's run did (the engine's verdict, :mod:`aiofl.engine.kernel.loop`): *ok*; *lost*,
# the plant left its operating envelope (the output's distance from the reference, the
# output's or a state's declared range), a fact about the plant; *diverged*, the numbers
# blew up (non-finite, or a plant state beyond the divergence threshold).  The observer's
# states never make a run lost; a non-finite controller state makes it diverged.
STATUS_OK = 0
STATUS_DIVERGED = 1
STATUS_LOST = 2
STATUS_NAMES = MappingProxyType({STATUS_OK: "ok", STATUS_DIVERGED: "diverged", STATUS_LOST: "lost"})

# --------------------------------------------------------------------- integer row
I_ESO, I_TD, I_SEF, I_LAW, I_RHO, I_NFB, I_ESO_INIT, I_ESO_MODEL, I_ESO_GAINS = range(9)
N_INT = 9
INT_NAMES = (
    "eso.kind",
    "td.kind",
    "sef.kind",
    "law.kind",
    "rho",
    "sef.n_feedback",
    "eso.init",
    "eso.model",
    "eso.gains",
)


def _float_columns() -> dict[str, int]:
    names: list[str] = ["law.b0", "law.u_max", "law.u_min", "eso.omega0"]
    names += [f"eso.alpha{i}" for i in range(1, RHO_MAX + 2)]
    names += ["eso.k_alpha", "eso.k_beta", "eso.g_alpha", "eso.g_beta"]
    # Kalman gains (eso.gains = "kalman"): process- and measurement-noise intensities; the
    # host writes the equivalent eso.omega0 and eso.alpha* from them (controller_batch)
    names += ["eso.q", "eso.r"]
    # the command held at the start (a bumpless start at an operating point): the extended
    # state starts at -b0 u0, so u(t0) = u0 (eso.init = "output" / "bumpless")
    names += ["eso.u0"]
    # the known measurement delay [s] (a whole number of samples) the discrete controller
    # compensates: its ESO is fed the command that delay old and its reference is delayed
    # by it, aligned with the delayed measurement (aiofl.engine.kernel.sampled)
    names += ["eso.delay"]
    names += ["td.R", "td.a", "td.b", "td.c", "td.rho", "td.omega"]
    for vec in ("k", "alpha", "delta", "kb", "mu"):
        names += [f"sef.{vec}{i}" for i in range(1, RHO_MAX + 1)]
    names += ["sef.v_limit", "sef.omega_c"]
    return {name: i for i, name in enumerate(names)}


FLOAT_COLUMNS: MappingProxyType[str, int] = MappingProxyType(_float_columns())
"""Column index of every float parameter, by name."""
N_FLOAT = len(FLOAT_COLUMNS)

F_B0 = FLOAT_COLUMNS["law.b0"]
F_UMAX = FLOAT_COLUMNS["law.u_max"]
F_UMIN = FLOAT_COLUMNS["law.u_min"]
"""Lower actuator limit; NaN (the default) means -u_max, a symmetric range."""
F_OMEGA0 = FLOAT_COLUMNS["eso.omega0"]
F_ESO_ALPHA = FLOAT_COLUMNS["eso.alpha1"]
F_ESO_K_ALPHA = FLOAT_COLUMNS["eso.k_alpha"]
F_ESO_K_BETA = FLOAT_COLUMNS["eso.k_beta"]
F_ESO_G_ALPHA = FLOAT_COLUMNS["eso.g_alpha"]
F_ESO_G_BETA = FLOAT_COLUMNS["eso.g_beta"]
F_ESO_Q = FLOAT_COLUMNS["eso.q"]
F_ESO_R = FLOAT_COLUMNS["eso.r"]
F_ESO_U0 = FLOAT_COLUMNS["eso.u0"]
F_ESO_DELAY = FLOAT_COLUMNS["eso.delay"]
KNOWN_DELAY_MAX = 8
"""The longest known delay a discrete controller compensates, in samples."""
F_TD_R = FLOAT_COLUMNS["td.R"]
F_TD_A = FLOAT_COLUMNS["td.a"]
F_TD_B = FLOAT_COLUMNS["td.b"]
F_TD_C = FLOAT_COLUMNS["td.c"]
F_TD_RHO = FLOAT_COLUMNS["td.rho"]
F_TD_OMEGA = FLOAT_COLUMNS["td.omega"]
F_SEF_K = FLOAT_COLUMNS["sef.k1"]
F_SEF_ALPHA = FLOAT_COLUMNS["sef.alpha1"]
F_SEF_DELTA = FLOAT_COLUMNS["sef.delta1"]
F_SEF_KB = FLOAT_COLUMNS["sef.kb1"]
F_SEF_MU = FLOAT_COLUMNS["sef.mu1"]
F_SEF_V_LIMIT = FLOAT_COLUMNS["sef.v_limit"]
F_SEF_OMEGA_C = FLOAT_COLUMNS["sef.omega_c"]

# ------------------------------------------------------------------- scenario row
S_REF_KIND, S_REF_A, S_REF_OMEGA, S_REF_PHASE, S_REF_OFFSET, S_REF_TSTEP = range(6)
S_DIST_AMP, S_DIST_TIME, S_PCHANGE_TIME, S_NOISE_STD, S_NOISE_HOLD = range(6, 11)
S_REF_DT = 11  # sample spacing of a REF_SAMPLES reference
S_IN_DELAY = 12  # input (actuator) transport delay [s]: the plant sees u(t - τ_in)
S_OUT_DELAY = 13  # output (sensor) transport delay [s]: the ADC reads y(t - τ_out)
S_ENVELOPE = 14  # |y - r| above it: the run is lost (inf: no envelope)
S_U_REF = 15  # ISU and IAU measure u - u_ref (the holding input at the operating point)
S_STEADY_FROM = 16  # the steady-state window starts here [s] (noise in u, steady error)
N_SCEN = 17

# ------------------------------------------------------ what the loop watches per member
# (aiofl.engine.kernel.loop._tpl_watch, at every step t_k on the plant's y = h(x_k), the reference
# r(t_k) and the command u applied over the step)
ST_U_PEAK = 0  #: max |u|
ST_T_SAT = 1  #: time with u at the actuator's limit [s]
ST_E_PEAK = 2  #: max |y - r|
ST_STEP_PEAK = 3  #: step reference: max of sign(A)(y - r0) from the step on
ST_T10 = 4  #: step reference: first time sign(A)(y - r0) >= 0.1 |A| (NaN: never)
ST_T90 = 5  #: step reference: first time sign(A)(y - r0) >= 0.9 |A| (NaN: never)
ST_T_OUT = 6  #: step reference: last time |y - r| >= 2 % |A| (NaN: never)
ST_SS_N = 7  #: steps in the steady-state window
ST_SS_U0 = 8  #: the window's first u (the shift of the sums below)
ST_SS_SU = 9  #: sum of u - u0 over the window
ST_SS_SU2 = 10  #: sum of (u - u0)^2 over the window
ST_SS_SE = 11  #: sum of y - r over the window
ST_Y_END = 12  #: y - r at the last step watched
ST_U_LAST = 13  #: u at the previous step watched
ST_SS_DU2 = 14  #: sum over the window of (u_k - u_{k-1})^2 where u changed
ST_SS_NDU = 15  #: the steps in the window where u changed
N_STAT = 16

# ------------------------------------------------------------------ metric columns
METRIC_NAMES = ("itae", "iae", "ise", "isu", "iau")
M_ITAE, M_IAE, M_ISE, M_ISU, M_IAU = range(5)
N_METRIC = len(METRIC_NAMES)

RESPONSE_NAMES = (
    "overshoot",
    "rise_time",
    "settling_time",
    "steady_error",
    "u_std",
    "u_noise",
    "u_rms",
    "u_peak",
    "e_peak",
    "saturated_time",
)
"""What the loop watched, as figures (:mod:`aiofl.engine.response`): step metrics, the
command at steady state, peaks, the time at the actuator's limit; NaN where one does not
apply (no step reference) or was not reached (never settled)."""
SCORE_NAMES = METRIC_NAMES + RESPONSE_NAMES
"""Everything a tuner can minimise or bound per run: the integrals, then the figures."""
N_SCORE = len(SCORE_NAMES)


def trajectory_columns(n_states: int) -> tuple[str, ...]:
    """Names of the columns the engine stores per saved time point.

    ``t, r, y, y_meas, u, d`` then the plant state ``x1..xn``, the observer state
    ``xi_hat1..xi_hat{ρmax+1}`` and the differentiator state ``r1..r{ρmax}``.
    """
    cols = ["t", "r", "y", "y_meas", "u", "d"]
    cols += [f"x{i}" for i in range(1, n_states + 1)]
    cols += [f"xi_hat{i}" for i in range(1, RHO_MAX + 2)]
    cols += [f"r{i}" for i in range(1, RHO_MAX + 1)]
    return tuple(cols)
