r"""The controller object for test rigs and hardware in the loop: ``u = ctrl.step(r, y)``.

:class:`DiscreteController` is the engine's discrete controller stepped from Python: the
compiled update ``aiofl simulate --ts`` runs (:mod:`aiofl.engine.kernel.sampled`), compiled
without a plant (:mod:`aiofl.engine.build.controller_update`), what the exported C is checked
against and what the sampled loop's linearisation steps, with a constructor from a
config::

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
from aiofl.checks import check_number
from aiofl.config import RunConfig, load_config
from aiofl.controller import Controller, controller_batch
from aiofl.engine.build.controller_update import NO_TABLE, compiled_update, member_constants
from aiofl.engine.discrete_rows import Sampling
from aiofl.engine.kernel import member
from aiofl.engine.kernel.member import IQ_EINIT
from aiofl.engine.kernel.sampled import C_RPREV, C_TD, C_X, N_CS
from aiofl.engine.observer_gains import model_jacobians
from aiofl.engine.sample_time import SIGNAL_MAX, TS_MAX, TS_MIN, check_ts, discrete_row

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


class DiscreteController:
    r"""The engine's discrete controller, stepped from Python one sample at a time.

    The same compiled update the sampled engine runs
    (:func:`aiofl.engine.kernel.sampled._tpl_ctrl_step`, compiled without a plant by
    :mod:`aiofl.engine.build.controller_update`), with the coefficients of
    :func:`aiofl.engine.discrete_rows.sampling_rows`.  One call per sample: :meth:`init` with
    the first measurement (or :meth:`reset`, a bumpless start), then :meth:`step` with the
    reference (and its derivatives) and the measurement, returning u.

    Refusals and faults (the same in the exported C and the FMU,
    :mod:`aiofl.engine.sample_time`): the sample time must be a number in [1e-9, 1] s at
    which the design can be discretised (ValueError naming ``ts``, with the design's range),
    and the design's coefficients finite.  A measurement ``y`` or a reference value the
    controller reads that is not finite or beyond ±1e30, or an update that would make the
    command or the state non-finite, is a fault: the sample changes nothing, the last
    command (before the first: the start's ``eso.u0``, 0 by default) is returned, and
    :attr:`fault` stays True, every later sample ignored with the command held, until
    :meth:`init` or :meth:`reset`.  :meth:`step_each` (the Jacobians of the update) runs
    the update as it is, without the fault policy.

    Parameters
    ----------
    controller
        An AIOFL controller (LESO, INLESO, LADRC, ...); the IOFL law needs the plant state
        and is refused.
    sampling
        Sample time and discretisation (:class:`aiofl.engine.discrete_rows.Sampling`); ``ts``
        must be a number in [1e-9, 1] s at which the design can be discretised.
    plant
        The plant whose nominal model a model-assisted observer (``eso.model =
        "nominal"``) carries, with its nominal parameters; not needed otherwise (default
        None).
    x0
        The plant state the model-assisted observer's bandwidth gains are placed at, as the
        engine places them at the scenario's initial state:
        :math:`J = \partial(\hat\alpha + \hat\beta u^*)/\partial\xi` at
        :math:`\xi^* = \Phi(x_0)` (:func:`aiofl.engine.observer_gains.model_jacobians`);
        empty (the default): the origin.  Not used otherwise.
    """

    def __init__(
        self,
        controller: Controller,
        sampling: Sampling,
        plant: Any = None,
        x0: Sequence[float] = (),
    ) -> None:
        check_ts(sampling.ts, "ts")
        if controller.law != "aiofl":
            raise ValueError(
                f"controller.law_kind = {controller.law!r}: a discrete controller without "
                "the plant needs the AIOFL law (the IOFL law evaluates the plant model)"
            )
        sampling.check(controller)
        model = controller.eso_model != "none"
        if model:
            if plant is None:
                raise ValueError(
                    f"controller.eso.model = {controller.eso_model!r}: the discrete controller "
                    "evaluates the plant's nominal model; pass plant="
                )
            controller.check_plant(plant)
        self.controller = controller
        self.sampling = sampling
        # a model-assisted observer's gain is placed for the model's error map at Φ(x0)
        jac = model_jacobians(plant, controller_batch(controller), [x0]) if model else None
        self.row = discrete_row(controller, sampling, jac)  # a failing Ts named, with its range
        self._fn = compiled_update(plant if model else None)
        self._pn = plant.param_vector() if plant is not None else np.zeros(1)
        self._q, self._iq = member_constants(self._fn, controller)
        derived = self._q[L.N_FLOAT :]
        if not np.all(np.isfinite(derived)):
            first = L.N_FLOAT + int(np.flatnonzero(~np.isfinite(derived))[0])
            what = next(w for lo, hi, w in _Q_SLOTS if lo <= first < hi)
            raise ValueError(
                f"controller: the design's {what} are not finite; allowed: parameters whose "
                "coefficients are finite numbers (a smaller value)"
            )
        self._cs = np.zeros(N_CS)
        self._scr = np.zeros(N_CS)
        self._rr = np.zeros((1, L.RHO_MAX + 2))
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
        r"""Reset the states for the first measurement ``y0`` as ``controller.eso_init``
        says, as the continuous loop starts it: ``"zero"`` (the default: prediction 0, the
        differentiator at 0, ``y0`` unused), ``"output"`` (:math:`\hat\xi_1 = y_0`, the
        other states 0) or ``"bumpless"`` (that and the differentiator at rest at ``y0``;
        :meth:`reset`).  Clears :attr:`fault` (unless ``y0`` is not usable)."""
        y = _real(y0, "y0")
        self._fn.init(self._iq, self._q, self._cs, y)
        zero = self.controller.eso_init == "zero"
        self._start(zero or _usable(y), 0.0 if zero else self.controller.value("eso.u0"))

    def reset(self, y0: float, u0: float | None = None) -> None:
        r"""A bumpless (re)start at ``y0``, at any sample boundary, whatever the config's
        start: :math:`\hat\xi = (y_0, 0, ..., 0, -b_0 u_0)`, the differentiator at rest at
        ``y0``; a plant at rest at :math:`y_0 = r` gets :math:`u = u_0` next (the hand-over
        of a manual command ``u0``; None: the design's ``eso.u0``).  The model-assisted
        observer starts at its model's :math:`-\hat\alpha/\hat\beta` (``u0`` refused).
        Clears :attr:`fault` (unless ``y0`` is not usable)."""
        y = _real(y0, "y0")
        iq = self._iq.copy()
        iq[IQ_EINIT] = L.ESO_INIT_BUMPLESS
        q = self._q.copy()
        if u0 is not None:
            q[L.F_ESO_U0] = check_number("u0", u0, finite=True)
            if u0 != 0.0 and self.controller.eso_model != "none":
                raise ValueError(f"u0 = {u0}: the model-assisted observer takes no u0")
        self._fn.init(iq, q, self._cs, y)
        self._start(_usable(y), self.controller.value("eso.u0") if u0 is None else float(u0))

    def _reference(self, r: float | Sequence[float] | NDArray[np.float64]) -> None:
        """``r`` (r, or r, r', ...) into the reference row the update reads."""
        rv = np.atleast_1d(np.asarray(r, dtype=np.float64))
        self._rr[0, :] = 0.0
        self._rr[0, : rv.size] = rv

    def _update_args(self, cs: NDArray[np.float64], y: float | NDArray[np.float64]) -> tuple:
        """The arguments of the compiled update up to the nominal parameters (the plant
        table is unread: α, β are called directly), from the controller state ``cs`` and
        the measurement(s) ``y``."""
        return (NO_TABLE, self._iq, self._q, self.row, cs, self._scr, y, self._rr, 0, self._pn)

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
        self._reference(rv)
        args = self._update_args(self._cs, yv)
        u = float(self._fn.step(*args) if n is None else self._fn.run(*args, n))
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

    def step_each(
        self,
        states: NDArray[np.float64],
        r: float | Sequence[float] | NDArray[np.float64],
        ys: NDArray[np.float64],
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """One sample from each of several controller states (rows of ``states``, shape
        (K, len(state))) with the measurements ``ys`` (K,) and one reference ``r``:
        ``(next states, commands)``, as :meth:`step` from each (the controller's own
        state is left alone), without the fault policy.  For finite-difference Jacobians of
        the update.

        Parameters
        ----------
        states
            The controller states, (K, len(state)).
        r
            The reference.
        ys
            The measurements, (K,).

        Returns
        -------
        states, commands : ndarray
        """
        st = np.array(states, dtype=np.float64, order="C", ndmin=2)
        yv = np.ascontiguousarray(ys, dtype=np.float64).reshape(-1)
        if st.ndim != 2 or st.shape[1] != self._cs.size or yv.size != st.shape[0]:
            raise ValueError(
                f"states has shape {st.shape} and ys {yv.shape}; allowed: (K, {self._cs.size}) "
                "and (K,)"
            )
        self._reference(r)
        us = np.empty(st.shape[0])
        self._fn.step_each(*self._update_args(st, yv), us)
        return st, us

    @property
    def state(self) -> NDArray[np.float64]:
        """A copy of the whole controller state (the engine's ``cs`` vector: differentiator,
        ESO prediction and estimate, previous command, measurement and reference, ...);
        assign to it to set the state (for the one-sample Jacobian of
        :mod:`aiofl.analysis.sampled_loop`)."""
        return self._cs.copy()

    @state.setter
    def state(self, value: NDArray[np.float64]) -> None:
        v = np.asarray(value, dtype=np.float64)
        if v.shape != self._cs.shape:
            raise ValueError(f"state has shape {v.shape}; allowed: {self._cs.shape}")
        self._cs[:] = v

    @property
    def estimate(self) -> NDArray[np.float64]:
        """The ESO estimate ξ̂ after the last sample's correction (ρ+1 values)."""
        return self._cs[C_X : C_X + self.controller.rho + 1].copy()

    @property
    def differentiator(self) -> NDArray[np.float64]:
        """The differentiator's (or prefilter's) state, already advanced to the next sample."""
        out = self._cs[C_TD : C_TD + L.RHO_MAX].copy()
        if self.controller.td == "han":  # kept as r_1 - r_prev
            out[0] += self._cs[C_RPREV]
        return out

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
