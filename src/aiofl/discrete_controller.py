r"""The controller object for test rigs and hardware in the loop: ``u = ctrl.step(r, y)``.

:class:`DiscreteController` is the engine's discrete controller
(:class:`aiofl.engine.standalone.DiscreteController`: the compiled update ``aiofl simulate
--ts`` runs and the exported C is checked against) with a constructor from a config::

    ctrl = aiofl.DiscreteController.from_config("assisted-s1-ladrc")   # its sensor's Ts
    ctrl.reset(y0)                       # bumpless start at the first measurement
    while running:                       # every Ts
        u = ctrl.step(r, y)              # r (or r, r', ..., r^(rho)) and y at t_k

The arguments are (r, y), in the order of the exported C's ``NAME_step(s, p, r, y)``.

What it refuses and what it does with a sample it cannot use is one policy with the
exported C and the FMU (:mod:`aiofl.engine.sample_time`): a sample time that is not a number
in [1e-9, 1] s or that the design cannot be discretised at, and non-finite coefficients,
are refused at construction, naming the argument; ``y`` and ``r`` of the wrong type or
shape raise at :meth:`~DiscreteController.step`; a measurement or reference that is not
finite or beyond ±1e30, or an update that would overflow, is a **fault**: the sample
changes nothing, the last command is returned and held, and :attr:`~DiscreteController.fault`
stays True until :meth:`~DiscreteController.init` or :meth:`~DiscreteController.reset`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from aiofl import layout as L
from aiofl.config import RunConfig, load_config
from aiofl.controller import Controller
from aiofl.engine import member, standalone
from aiofl.engine.discrete import Sampling
from aiofl.engine.sample_time import SIGNAL_MAX, TS_MAX, TS_MIN, check_ts

__all__ = ["DiscreteController"]


_Q_SLOTS = (  # the derived constants of the packed parameters, and what they come from
    (member.Q_BETA, member.Q_FEEDBACK_GAIN, "eso.omega0 (the observer gains)"),
    (member.Q_FEEDBACK_GAIN, member.Q_SLOPE, "sef.omega_c or sef.k* (the feedback gains)"),
    (member.Q_SLOPE, member.Q_PF, "sef.delta* / sef.alpha* (fal's inner slopes)"),
    (member.Q_PF, member.Q_ITD_BC, "td.omega (the prefilter coefficients)"),
    (member.Q_ITD_BC, member.N_Q, "td.a, td.b, td.c (the ITD's constants)"),
)


def _real(value: Any, name: str) -> float:
    """``value`` as a float if it is one real number (not a bool); else TypeError naming
    ``name``."""
    if isinstance(value, float):
        return value
    if isinstance(value, np.ndarray) and value.ndim == 0:
        value = value[()]
    if isinstance(value, bool | np.bool_) or not isinstance(
        value, int | float | np.integer | np.floating
    ):
        raise TypeError(
            f"{name} = {value!r:.80} ({type(value).__name__}); allowed: one real number"
        )
    return float(value)


def _usable(value: float) -> bool:
    """Whether a measurement or reference value is one the controller uses (finite, within
    ±SIGNAL_MAX; NaN fails the comparison)."""
    return abs(value) <= SIGNAL_MAX


class DiscreteController(standalone.DiscreteController):
    __doc__ = (
        (standalone.DiscreteController.__doc__ or "")
        + """
    Refusals and faults (the same in the exported C and the FMU,
    :mod:`aiofl.engine.sample_time`): the sample time must be a number in [1e-9, 1] s at
    which the design can be discretised (ValueError naming ``ts``, with the design's range),
    and the design's coefficients finite.  A measurement ``y`` or a reference value the
    controller reads that is not finite or beyond ±1e30, or an update that would make the
    command or the state non-finite, is a fault: the sample changes nothing, the last
    command (before the first: the start's ``eso.u0``, 0 by default) is returned, and
    :attr:`fault` stays True, every later sample ignored with the command held, until
    :meth:`init` or :meth:`reset`.
    """
    )

    def __init__(
        self,
        controller: Controller,
        sampling: Sampling,
        plant: Any = None,
        x0: Sequence[float] = (),
    ) -> None:
        """The controller of ``controller`` sampled as ``sampling``, refused as the class notes say.

        Parameters
        ----------
        controller
            An AIOFL controller (LESO, INLESO, LADRC, ...); the IOFL law is refused.
        sampling
            Sample time and discretisation (:class:`aiofl.engine.discrete.Sampling`); ``ts`` must
            be a number in [1e-9, 1] s at which the design can be discretised.
        plant
            The plant whose nominal model a model-assisted observer (``eso.model = "nominal"``)
            carries; not needed otherwise (default None).
        x0
            The plant state the model-assisted observer's gains are placed at (default: the
            origin); not used otherwise.
        """
        check_ts(sampling.ts, "ts")
        super().__init__(controller, sampling, plant=plant, x0=x0)
        derived = self._q[L.N_FLOAT :]
        if not np.all(np.isfinite(derived)):
            first = L.N_FLOAT + int(np.flatnonzero(~np.isfinite(derived))[0])
            what = next(w for lo, hi, w in _Q_SLOTS if lo <= first < hi)
            raise ValueError(
                f"controller: the design's {what} are not finite; allowed: parameters whose "
                "coefficients are finite numbers (a smaller value)"
            )
        self._fault = False
        self._held = 0.0
        self._saved = np.empty_like(self._cs)
        self._zeros = np.zeros_like(self._cs)
        self._n_ref = controller.rho + 1

    @property
    def fault(self) -> bool:
        """Whether a sample was a fault (see the class notes) since the last :meth:`init` /
        :meth:`reset`: the command is held and samples are ignored until then."""
        return self._fault

    def init(self, y0: float) -> None:
        y = _real(y0, "y0")
        super().init(y)
        zero = self.controller.eso_init == "zero"
        self._start(zero or _usable(y), 0.0 if zero else self.controller.value("eso.u0"))

    def reset(self, y0: float, u0: float | None = None) -> None:
        y = _real(y0, "y0")
        super().reset(y, u0)
        self._start(_usable(y), self.controller.value("eso.u0") if u0 is None else float(u0))

    def _start(self, usable: bool, u0: float) -> None:
        """After a start: the start's command ``u0`` held (``eso.u0``, 0 unless set), the
        fault cleared unless the start measurement is not usable."""
        self._held = u0
        self._fault = not usable

    def _reference_values(self, r: Any) -> list[float]:
        """``r`` as the values r, r', ... (1 to ρ+1 real numbers); TypeError / ValueError
        naming ``r`` otherwise."""
        if isinstance(r, float):
            return [r]
        if isinstance(r, str | bytes) or r is None:
            raise TypeError(f"r = {r!r:.80}; allowed: a real number or 1 to {self._n_ref} of them")
        arr = np.asarray(r)
        if arr.dtype.kind not in "iuf":
            raise TypeError(
                f"r = {r!r:.80} (values of type {arr.dtype}); allowed: real numbers (r, r', "
                f"..., 1 to {self._n_ref} of them)"
            )
        if arr.ndim > 1 or not 1 <= arr.size <= self._n_ref:
            raise ValueError(
                f"r has shape {arr.shape}; allowed: a real number or a sequence of 1 to "
                f"{self._n_ref} (r, r', ..., r^(rho), rho = {self._n_ref - 1})"
            )
        return [float(v) for v in arr.reshape(-1)]

    def _read(self, values: list[float]) -> list[float]:
        """The reference values the update reads: r and its derivatives with the exact
        differentiator, r alone otherwise (as the exported C)."""
        return values if self.controller.td == "exact" else values[:1]

    def _sample(self, r: Any, y: Any, n: int | None) -> float:
        rv = self._reference_values(r)
        yv = _real(y, "y")
        if self._fault:
            return self._held
        if not (_usable(yv) and all(_usable(v) for v in self._read(rv))):
            self._fault = True
            return self._held
        self._saved[:] = self._cs
        u = super().step(rv, yv) if n is None else super().run(n, rv, yv)
        if not (math.isfinite(u) and self._cs.dot(self._zeros) == 0.0):  # NaN or inf in it
            self._cs[:] = self._saved
            self._fault = True
            return self._held
        self._held = u
        return u

    def step(self, r: float | Sequence[float] | NDArray[np.float64], y: float) -> float:
        """One sample: ``r`` = r (or r, ṙ, ..., r^(ρ)) at t_k, ``y`` the measurement; returns
        u (the held command after a fault, :attr:`fault`)."""
        return self._sample(r, y, None)

    def run(self, n: int, r: float | Sequence[float] | NDArray[np.float64], y: float) -> float:
        """``n`` samples (n ≥ 1) with the same reference ``r`` and measurement ``y`` in one
        compiled call (:meth:`step` n times); returns the last u.  A fault (:attr:`fault`)
        in any of them leaves the state as before the call.

        Parameters
        ----------
        n
            The number of samples, an integer in [1, 1e9].
        r
            The reference, as for :meth:`step`: r, or (r, r', ..., r^(ρ)).
        y
            The measurement, the same for every sample.

        Returns
        -------
        float
            The command u of the last sample (the held command after a fault).
        """
        if isinstance(n, bool) or not isinstance(n, int | np.integer) or not 1 <= n <= 10**9:
            raise ValueError(f"n = {n!r}; allowed: an integer, 1 <= n <= 1e9")
        return self._sample(r, y, int(n))

    @classmethod
    def from_config(cls, config: Any, ts: float | None = None) -> DiscreteController:
        r"""The discrete controller of a design.

        ``u = ctrl.step(r, y)`` once per sample, after ``ctrl.init(y0)`` (the config's
        ``eso.init``) or ``ctrl.reset(y0)`` (a bumpless start): the same numbers as
        ``aiofl simulate --ts`` and the exported C.

        Parameters
        ----------
        config
            A loaded config (:class:`aiofl.config.RunConfig`), a preset name or the path
            of a TOML config.
        ts
            Sample time [s]; default the config's (``[sensor] ts`` or
            ``[controller.discrete] ts``).  The config's discretisation options are kept.

        Raises
        ------
        TypeError
            For a ``ts`` that is not a number (``True`` included).
        ValueError
            Without a sample time, for ``1e-9 <= ts <= 1`` violated, for a ``ts`` the
            design cannot be discretised at (with the range it can), for non-finite
            coefficients, or for a controller the discrete update cannot run (the IOFL law).
        aiofl.config.ConfigError
            For a config that does not load.

        Examples
        --------
        The first call compiles the controller's update (seconds; cached on disk after):

        >>> ctrl = DiscreteController.from_config("tank-ladrc", ts=0.01)  # doctest: +SKIP
        >>> ctrl.reset(0.0)  # bumpless start at the first measurement  # doctest: +SKIP
        >>> ctrl.step(1.0, 0.0)  # r, y: u at its limit u_max = 10  # doctest: +SKIP
        10.0
        """
        if ts is not None:
            ts = check_ts(ts, "ts")  # before the config is loaded: the argument named first
        cfg = config if isinstance(config, RunConfig) else load_config(config)
        if ts is None:
            if cfg.sampling is None:
                raise ValueError(
                    f"{cfg.name!r} has no sample time ([sensor] ts); pass ts= "
                    f"(allowed: {TS_MIN:g} <= ts <= {TS_MAX:g} [s])"
                )
            sampling = cfg.sampling
        else:
            sampling = replace(cfg.sampling or Sampling(ts), ts=ts)
        return cls(cfg.controller, sampling, plant=cfg.plant, x0=cfg.scenario.x0)
