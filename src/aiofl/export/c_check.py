r"""The exported C run on the host: build it, load it with ctypes, drive it in closed loop.

Used by ``aiofl export --precision float`` to check that single precision holds for the
design (:func:`float_holds`) and by the tests.  The plant runs in a compiled RK4
(:func:`advancer`, the plant's own numba functions, :math:`\dot x = f + g u + b_d d`), so a
20-s loop at Ts = 1 ms takes about a second; the controller is any ``step(r, y) -> u``
callable: the C (:class:`CController`) or the engine's
:class:`aiofl.discrete_controller.DiscreteController`.
"""

from __future__ import annotations

import ctypes
import math
import shutil
import subprocess
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from aiofl import layout as L
from aiofl.scenario import Reference

CC = shutil.which("cc") or shutil.which("gcc")
WARN = ["-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic"]
STRICT_FLOAT = ["-Wconversion", "-Wdouble-promotion"]
START = {"bumpless": 0, "zero": 1, "output": 2}


def build(
    folder: Path, files: dict[str, str], extra: Sequence[str] = (), name: str = "libctl.so"
) -> Path:
    """Write ``files`` into ``folder`` and link every ``.c`` into a shared library.

    Parameters
    ----------
    folder
        The folder to write into (created if missing).
    files
        ``{file name: text}``, as :func:`aiofl.export.export_c` gives them.
    extra
        More compiler flags (``-DNAME=...``).
    name
        The library's file name (default ``"libctl.so"``).

    Returns
    -------
    Path
        The shared library.

    Raises
    ------
    RuntimeError
        When the C does not compile (with the compiler's message).
    """
    folder.mkdir(parents=True, exist_ok=True)
    for fname, text in files.items():
        (folder / fname).write_text(text)
    sources = sorted(str(folder / n) for n in files if n.endswith(".c"))
    lib = folder / name
    cmd = [str(CC), *WARN, *extra, "-O2", "-shared", "-fPIC", "-o", str(lib), *sources, "-lm"]
    proc = subprocess.run(cmd, capture_output=True, text=True, check=False)
    if proc.returncode != 0:
        raise RuntimeError(f"the exported C did not compile: {proc.stderr[:2000]}")
    return lib


class CController:
    """An exported controller in a shared library: ``start(y0, mode)``, ``step(r, y)``."""

    def __init__(
        self,
        lib: Path | ctypes.CDLL,
        precision: str,
        prefix: str = "aiofl",
        params: str = "",
        signal: str = "double",
    ) -> None:
        """The exported controller loaded with :mod:`ctypes`.

        Parameters
        ----------
        lib
            The shared library (:func:`build`), a path or a loaded ``ctypes.CDLL``.
        precision
            ``"double"`` or ``"float"``: the C type ``NAME_real`` the library was built with.
        prefix
            The exported names' prefix (default ``"aiofl"``).
        params
            The parameter instance to step with (default ``PREFIX_default_params``).
        signal
            The C type of the measurement and reference, ``NAME_signal`` (default ``"double"``).
        """
        self.lib = lib if isinstance(lib, ctypes.CDLL) else ctypes.CDLL(str(lib))
        real = ctypes.c_double if precision == "double" else ctypes.c_float
        sig = ctypes.c_double if signal == "double" else ctypes.c_float  # NAME_signal
        self._start = getattr(self.lib, f"{prefix}_start")
        self._start.argtypes = [ctypes.c_void_p, ctypes.c_void_p, sig, ctypes.c_int]
        self._start.restype = None
        self._reset = getattr(self.lib, f"{prefix}_reset")
        self._reset.argtypes = [ctypes.c_void_p, ctypes.c_void_p, sig]
        self._reset.restype = None
        self._step = getattr(self.lib, f"{prefix}_step")
        self._step.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.POINTER(sig), sig]
        self._step.restype = real
        self.state = (ctypes.c_double * 64)()  # larger than any state, double-aligned
        self.rbuf = (sig * (L.RHO_MAX + 1))()
        self.use(params or f"{prefix}_default_params")

    def use(self, params: str) -> None:
        """Step with the parameter instance named ``params`` from now on."""
        self.params = ctypes.addressof(ctypes.c_char.in_dll(self.lib, params))

    def start(self, y0: float, mode: str = "bumpless") -> None:
        self._start(self.state, self.params, y0, START[mode])

    def reset(self, y0: float) -> None:
        self._reset(self.state, self.params, y0)

    def step(self, r: Sequence[float], y: float) -> float:
        for i, v in enumerate(r):
            self.rbuf[i] = v
        return float(self._step(self.state, self.params, self.rbuf, y))


def reference(ref: Reference, t: float, rho: int) -> list[float]:
    """r, ṙ, ..., r^(ρ) of a sine reference at t (r alone, held derivatives 0, otherwise).

    Parameters
    ----------
    ref
        The reference.
    t
        The time [s].
    rho
        The highest derivative, ρ.

    Returns
    -------
    list of float
        ρ + 1 values.
    """
    if ref.kind != "sine":
        return [float(ref.evaluate(t))] + [0.0] * rho
    out = [
        ref.amplitude * ref.omega**k * math.sin(ref.omega * t + ref.phase + k * math.pi / 2)
        for k in range(rho + 1)
    ]
    out[0] += ref.offset
    return out


_ADVANCERS: dict[str, Any] = {}


def advancer(plant: Any) -> Callable[..., np.ndarray]:
    """``advance(x, u, d, p, dt, n)``: n RK4 steps of :math:`\\dot x = f + g u + b_d d`."""
    if plant.name not in _ADVANCERS:
        from numba import njit

        f, g, _, bd = plant.compiled[:4]

        @njit(cache=False)
        def rhs(x, u, d, p, out):  # pragma: no cover - compiled
            fx, gx, bx = f(x, p), g(x, p), bd(x, p)
            for i in range(x.size):
                out[i] = fx[i] + gx[i] * u + bx[i] * d
            return out

        @njit(cache=False)
        def advance(x, u, d, p, dt, n):  # pragma: no cover - compiled
            k1, k2, k3, k4 = np.empty_like(x), np.empty_like(x), np.empty_like(x), np.empty_like(x)
            for _ in range(n):
                rhs(x, u, d, p, k1)
                rhs(x + 0.5 * dt * k1, u, d, p, k2)
                rhs(x + 0.5 * dt * k2, u, d, p, k3)
                rhs(x + dt * k3, u, d, p, k4)
                x = x + dt / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
            return x

        _ADVANCERS[plant.name] = advance
    return _ADVANCERS[plant.name]  # type: ignore[no-any-return]


def loop(
    step: Callable[[list[float], float], float],
    plant: Any,
    ref: Reference,
    rho: int,
    ts: float,
    t_final: float,
    *,
    x0: Sequence[float] = (),
    scale: dict[str, float] | None = None,
    disturbance: tuple[float, float] = (0.0, 0.0),
    delay: int = 0,
    n_sub: int = 10,
    u_start: float = 0.0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Drive ``plant`` (true parameters scaled by ``scale``; a step disturbance
    ``(amplitude, time)``) with ``step`` at Ts; returns (t, y, u) at the samples (u the
    command computed at t_k; with ``delay`` it is applied over the next interval, the first
    interval getting ``u_start``, the command the controller holds at its start).

    Parameters
    ----------
    step
        ``step(r, y) -> u``: the controller, with r the list of ρ + 1 reference values.
    plant
        The plant (its compiled kernel advances the state).
    ref, rho
        The reference and the number of its derivatives the controller reads.
    ts, t_final
        The sample time and the horizon [s].
    x0
        The start state (empty: zeros).
    scale
        Factors of the true parameters, by name.
    disturbance
        The step disturbance (amplitude, time [s]).
    delay
        Non-zero: a sample of computation delay (each command is applied over the next
        interval).
    n_sub
        RK4 substeps of the plant per sample.
    u_start
        The command applied over the first interval with ``delay``.

    Returns
    -------
    t, y, u : ndarray
        At the samples; cut short where the state stops being finite or |y| > 1e6.
    """
    names = plant.param_names
    p = plant.param_vector().copy()
    for k, v in (scale or {}).items():
        p[names.index(k)] *= v
    h = plant.compiled[2]
    adv = advancer(plant)
    x = np.zeros(plant.n_states) if not len(x0) else np.asarray(x0, dtype=np.float64)
    n = round(t_final / ts)
    ts_, ys, us = np.arange(n) * ts, np.empty(n), np.empty(n)
    applied = 0.0
    for k in range(n):
        t = k * ts
        y = float(h(x, p))
        u = step(reference(ref, t, rho), y)
        applied = (us[k - 1] if k else u_start) if delay else u
        ys[k], us[k] = y, u
        d = disturbance[0] if disturbance[0] and t >= disturbance[1] else 0.0
        x = adv(x, applied, d, p, ts / n_sub, n_sub)
        if not np.all(np.isfinite(x)) or abs(y) > 1e6:
            return ts_[: k + 1], ys[: k + 1], us[: k + 1]
    return ts_, ys, us


def itae_isu(t: np.ndarray, y: np.ndarray, u: np.ndarray, ref: Reference, ts: float) -> tuple:
    """ITAE = sum t|r - y| Ts and ISU = sum u^2 Ts over the samples.

    Parameters
    ----------
    t, y, u
        The samples of :func:`loop`.
    ref
        The reference.
    ts
        The sample time [s].

    Returns
    -------
    itae, isu : float
    """
    e = ref.evaluate(t) - y
    return float(np.sum(t * np.abs(e)) * ts), float(np.sum(u * u) * ts)


FLOAT_ITAE_TOL = 0.05
FLOAT_ISU_TOL = 0.02


def float_holds(cfg: Any, sampling: Any, files: dict[str, dict[str, str]]) -> str | None:
    r"""Why the float build of ``cfg``'s controller does not hold, or None if it does.

    Runs the config's scenario (plant with its scale and load step, sine or step reference)
    in closed loop at ``sampling.ts`` with the double and the float C of ``files``
    (``{"double": files, "float": files}``, prefix ``aiofl``), both fed the same exact
    measurement, and compares :math:`\mathrm{ITAE} = \sum t_k|r_k - y_k|T_s` (within
    :data:`FLOAT_ITAE_TOL`) and :math:`\mathrm{ISU} = \sum u_k^2 T_s` (within
    :data:`FLOAT_ISU_TOL`).  Raises RuntimeError without a C compiler.

    Parameters
    ----------
    cfg
        The run config.
    sampling
        Its sampling (:class:`aiofl.engine.discrete_rows.Sampling`).
    files
        The C files by precision, ``{"double": ..., "float": ...}``.

    Returns
    -------
    str or None
        The reason the float build does not hold, or None.
    """
    import tempfile

    if CC is None:
        raise RuntimeError("no C compiler (cc or gcc) on PATH")
    c, sc = cfg.controller, cfg.scenario
    out = {}
    with tempfile.TemporaryDirectory(prefix="aiofl-float-check-") as tmp:
        for prec, fs in files.items():
            cc = CController(build(Path(tmp) / prec, fs), prec)
            started: list[bool] = []

            def step(
                r: list[float], y: float, cc: CController = cc, st: list[bool] = started
            ) -> float:
                if not st:
                    cc.start(y, c.eso_init)
                    st.append(True)
                return cc.step(r, y)

            t, y, u = config_loop(step, cfg, sampling)
            if len(t) < round(sc.t_final / sampling.ts):
                return f"the {prec} build diverges at {t[-1]:.3g} s"
            out[prec] = itae_isu(t, y, u, sc.reference, sampling.ts)
    (i_d, s_d), (i_f, s_f) = out["double"], out["float"]
    di, ds = abs(i_f / i_d - 1.0), abs(s_f / s_d - 1.0)
    if di <= FLOAT_ITAE_TOL and ds <= FLOAT_ISU_TOL:
        return None
    return (
        f"in float its ITAE differs from double by {100 * di:.3g} % and its ISU by "
        f"{100 * ds:.3g} % (allowed {100 * FLOAT_ITAE_TOL:g} %, {100 * FLOAT_ISU_TOL:g} %)"
    )


def config_loop(
    step: Callable[[list[float], float], float], cfg: Any, sampling: Any
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`loop` over a run config's scenario (its plant scale, load step, reference,
    start state and horizon) at ``sampling``'s Ts and computation delay.

    Parameters
    ----------
    step
        ``step(r, y) -> u``, as for :func:`loop`.
    cfg
        The run config.
    sampling
        The sample time and computation delay.

    Returns
    -------
    t, y, u : ndarray
    """
    sc = cfg.scenario
    return loop(
        step,
        cfg.plant,
        sc.reference,
        cfg.controller.rho,
        sampling.ts,
        sc.t_final,
        x0=sc.x0,
        scale=dict(sc.plant_scale),
        delay=sampling.delay,
        disturbance=(sc.disturbance_amplitude, sc.disturbance_time),
        u_start=start_command(cfg.controller),
    )


def start_command(controller: Any) -> float:
    """The command a controller holds from its start to its first sample: ``eso.u0``
    (0 with a zero start)."""
    return 0.0 if controller.eso_init == "zero" else controller.value("eso.u0")


def engine_agreement(cfg: Any, sampling: Any, files: dict[str, str]) -> dict[str, float]:
    r"""The exported C (``files``, prefix ``aiofl``) against the engine's discrete
    controller (:class:`aiofl.discrete_controller.DiscreteController`) in the config's closed
    loop at ``sampling.ts``: both started as the config says and fed the same measurement
    and reference at every sample, the plant driven by the C's command.

    Returns ``{"samples", "max_abs_du", "max_abs_u", "relative"}``: the largest
    :math:`|u_C - u_{engine}|`, the largest :math:`|u|` and their ratio (double precision
    C: rounding only, ~1e-13).  Raises RuntimeError without a C compiler.

    Parameters
    ----------
    cfg, sampling
        The run config and its sampling.
    files
        The exported double-precision C files.

    Returns
    -------
    dict
    """
    import tempfile

    from aiofl.discrete_controller import DiscreteController

    if CC is None:
        raise RuntimeError("no C compiler (cc or gcc) on PATH")
    c, sc = cfg.controller, cfg.scenario
    model = cfg.plant if c.eso_model != "none" else None
    eng = DiscreteController(c, sampling, model, tuple(sc.x0))
    du: list[float] = []
    with tempfile.TemporaryDirectory(prefix="aiofl-export-check-") as tmp:
        cc = CController(build(Path(tmp), files), "double")

        def step(r: list[float], y: float) -> float:
            if not du:
                cc.start(y, c.eso_init)
                eng.init(y)
            u_c, u_e = cc.step(r, y), eng.step(r[: c.rho + 1], y)
            du.append(abs(u_c - u_e))
            return u_c

        _, _, u = config_loop(step, cfg, sampling)
    worst, peak = max(du), float(np.max(np.abs(u)))
    return {
        "samples": float(len(du)),
        "max_abs_du": worst,
        "max_abs_u": peak,
        "relative": worst / peak if peak > 0 else worst,
    }
