"""Bounds on every size an input can ask for, checked before anything is allocated.

A config, a command-line override or a ``[tune]`` table that asks for more than these is
refused with a message naming the field, its value and the limit (exit status 2 on the
command line).  The numbers are stated in the manual's limits page (``docs/reference/limits.md``).

=============================  ===========================================================
limit                          what it bounds
=============================  ===========================================================
:data:`T_FINAL_MAX`            the horizon [s]
:data:`DT_MAX`                 the fixed step [s]
:data:`MAX_STEPS`              integration steps per member, t_final/dt
:data:`MAX_TRAJECTORY_BYTES`   a stored trajectory, (steps/decimation + 1) x columns x 8
:data:`MAX_NOISE_SAMPLES`      the held measurement-noise table, t_final/noise_hold + 2
:data:`MAX_POPULATION`         members of one tuning generation (one batched engine call)
:data:`MAX_EVALUATIONS`        members of a whole tuning run, population x generations
:data:`MAX_PLANT_FILE_BYTES`   a plant file, read before it is parsed
:data:`MAX_STATES`             the states of a symbolic plant (and of a size-only instance)
:data:`MAX_LOG_BYTES`          a logged experiment's file (CSV or .npz), read before parsing
:data:`MAX_LOG_SAMPLES`        the samples (rows) of a logged experiment or an excitation
=============================  ===========================================================
"""

from __future__ import annotations

__all__ = [
    "DT_MAX",
    "MAX_EVALUATIONS",
    "MAX_LOG_BYTES",
    "MAX_LOG_SAMPLES",
    "MAX_NOISE_SAMPLES",
    "MAX_PLANT_FILE_BYTES",
    "MAX_POPULATION",
    "MAX_STATES",
    "MAX_STEPS",
    "MAX_TRAJECTORY_BYTES",
    "T_FINAL_MAX",
    "check_run_size",
]

#: largest horizon [s]
T_FINAL_MAX = 1e4
#: largest plant file read (1 MiB; the 32-state, 64-parameter plant the expression limits
#: allow fits in a fraction of it)
MAX_PLANT_FILE_BYTES = 1 << 20
#: most states of a symbolic plant: the analysis takes up to n Lie derivatives over n states
#: and n x n Jacobians, and numba compiles n-tuples (aiofl.plants.expressions)
MAX_STATES = 32
#: largest fixed step [s]
DT_MAX = 0.1
#: most integration steps per member, t_final/dt: 100x the paper's 20-s run at dt = 1e-4,
#: 2-7 s per member (the engine takes 0.1-0.35 us per RK4 step of the paper's SLFJM loops,
#: measured on this project's 2-core machine); beyond it a run is almost surely a typo in
#: dt or t_final, and a GA generation of 64 such members would take minutes
MAX_STEPS = 20_000_000
#: most bytes of a stored trajectory, (steps/decimation + 1) x columns x 8
MAX_TRAJECTORY_BYTES = 512 * 2**20
#: most measurement-noise samples per scenario, t_final/noise_hold (8 bytes each)
MAX_NOISE_SAMPLES = 20_000_000
#: members of one tuning generation: one engine call packs a (population x ~90) float row
#: table and per-member state; 10^4 is 150x the paper's GA population of 64
MAX_POPULATION = 10_000
#: members of a whole tuning run (population x generations): every one is kept in memory
#: and written to evaluations.csv (~100 bytes a row), so 10^6 is ~100 MB of output
MAX_EVALUATIONS = 1_000_000
#: most samples of a logged experiment (aiofl.identification.log) and of an excitation
#: signal: 2·10^6 rows are 33 min at 1 kHz; a grey-box fit simulates the whole log once per
#: candidate, so a longer log is a typo in the logger or a job for decimation first
MAX_LOG_SAMPLES = 2_000_000
#: largest log file read (256 MiB): 2·10^6 rows of four columns at ~30 characters a cell
#: fit, checked before a byte is parsed (an .npz's arrays are checked from their headers)
MAX_LOG_BYTES = 256 * 2**20


def check_run_size(
    t_final: float,
    dt: float,
    *,
    noise_hold: float | None = None,
    trajectory_columns: int | None = None,
    decimation: int = 1,
    what: str = "",
) -> int:
    r"""Refuse a run whose size is degenerate or unbounded; return its number of steps.

    Checked before anything is allocated:

    * the horizon is a whole number of steps, :math:`N = t_f/\Delta t`, within
      :math:`10^{-9}` relative (a horizon is never silently rounded), and :math:`N \ge 1`;
    * :math:`N \le` :data:`MAX_STEPS` per member;
    * the noise table, :math:`\lceil t_f/t_{hold}\rceil + 2 \le` :data:`MAX_NOISE_SAMPLES`;
    * a stored trajectory, :math:`(\lfloor N/d\rfloor + 1)\,C\,8` bytes for decimation
      d and C columns, :math:`\le` :data:`MAX_TRAJECTORY_BYTES`.

    Parameters
    ----------
    t_final, dt
        The horizon :math:`t_f` and the step :math:`\Delta t` [s].
    noise_hold
        The noise's hold time :math:`t_{hold}` [s] (None: no noise table).
    trajectory_columns, decimation
        C and d of a stored trajectory (None: nothing stored).
    what
        What is run, for the message.

    Returns
    -------
    int
        N, the number of steps.

    Raises
    ------
    ValueError
        Naming the fields, their values and the limit.
    """
    where = f" ({what})" if what else ""
    ratio = t_final / dt  # inf for dt = 5e-324: compared before it is rounded
    if not ratio >= 1 - 1e-9:
        raise ValueError(
            f"simulation.dt = {dt:g} s is longer than scenario.t_final = {t_final:g} s"
            f"{where}; allowed: dt <= t_final (at least one step)"
        )
    if not ratio <= MAX_STEPS + 0.5:
        raise ValueError(
            f"scenario.t_final / simulation.dt = {t_final:g} / {dt:g} = {ratio:.3g} steps"
            f"{where}; allowed: at most {MAX_STEPS:.0e} steps per member (raise dt or "
            "shorten t_final)"
        )
    n = round(ratio)
    if abs(n * dt - t_final) > 1e-9 * t_final:
        raise ValueError(
            f"scenario.t_final = {t_final!r} s is not a whole number of steps of "
            f"simulation.dt = {dt!r} s (t_final/dt = {ratio:.12g}){where}; allowed: t_final "
            "an integer multiple of dt (within 1e-9), e.g. "
            f"t_final = {n * dt:.12g}"
        )
    if noise_hold is not None:
        ratio = t_final / noise_hold  # the engine allocates ceil(ratio) + 2 samples
        samples = ratio + 2
        if not ratio <= MAX_NOISE_SAMPLES - 2:  # also refuses inf
            raise ValueError(
                f"scenario.t_final / scenario.noise_hold = {t_final:g} / {noise_hold:g} = "
                f"{samples:.3g} noise samples{where}; allowed: at most "
                f"{MAX_NOISE_SAMPLES:.0e} (raise noise_hold)"
            )
    if trajectory_columns is not None:
        nbytes = (n // decimation + 1) * trajectory_columns * 8
        if nbytes > MAX_TRAJECTORY_BYTES:
            raise ValueError(
                f"the stored trajectory needs {nbytes / 2**20:.0f} MiB ({n // decimation + 1} "
                f"points x {trajectory_columns} columns x 8 bytes; t_final = {t_final:g}, "
                f"dt = {dt:g}, simulation.decimation = {decimation}){where}; allowed: at most "
                f"{MAX_TRAJECTORY_BYTES // 2**20} MiB (raise decimation or dt)"
            )
    return n
