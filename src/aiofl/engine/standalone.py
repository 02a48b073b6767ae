r"""The discrete controller stepped from Python: :class:`DiscreteController`.

The sampled engine's controller update (:func:`aiofl.engine.sampled._tpl_ctrl_step`, its
start and its n-step and each-state variants) compiled without a plant's dynamics
(:func:`standalone_recipe`), one sample per call: what a test rig or a hardware-in-the-loop
harness runs, and what the exported C is checked against.
"""

from __future__ import annotations

import threading
from collections.abc import Sequence
from types import SimpleNamespace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from aiofl import layout as L
from aiofl.cache import cache_enabled
from aiofl.checks import check_number
from aiofl.controller import Controller, controller_batch
from aiofl.engine import bindings, member, plant_table
from aiofl.engine import compile as compile_
from aiofl.engine.discrete import Sampling
from aiofl.engine.member import IQ_EINIT, N_IQ, N_Q
from aiofl.engine.observer_gains import model_jacobians
from aiofl.engine.sample_time import discrete_row
from aiofl.engine.sampled import (
    C_RPREV,
    C_TD,
    C_X,
    N_CS,
    _bind,
    _opts,
    _sources,
    _tpl_ctrl_init,
    _tpl_ctrl_run,
    _tpl_ctrl_step,
    _tpl_ctrl_step_each,
    _tpl_delay_reference,
)

__all__ = ["DiscreteController", "standalone_recipe"]

_LOCK = threading.Lock()


_STANDALONE: dict[int, tuple[Any, SimpleNamespace]] = {}
_NO_TABLE = np.zeros(plant_table.N_TABLE, dtype=np.int64)
"""The plant table DiscreteController passes: unread (its update calls α, β directly)."""


def standalone_recipe(plant: Any = None) -> compile_.Recipe:
    """The recipe of the controller update compiled without the plant's dynamics (for
    :class:`DiscreteController`): the per-member setup, the start, the step, n steps at one
    measurement and one step from each of several states, each cached on disk; given
    ``plant``, with its nominal normal form ``alpha_beta_of_xi`` for the model-assisted
    observer."""
    from aiofl.plants.base import _no_alpha_beta

    # private copies of every compiled function it calls, as the loops' recipes bind: the
    # public ones are cached by numba beside their own source only, so a cached update
    # could link a stale callee (bindings.private_components)
    ns = dict(vars(member))
    bindings.bind_private(ns)
    ns.update(_N=1, _NZ=1, **bindings.component_functions())
    _bind(ns, bindings.private_components()["discrete"])
    ab = plant.compiled[5] if plant is not None else _no_alpha_beta
    # the plant's α, β called directly (its table argument unread: DiscreteController
    # passes an empty one)
    own_ab = compile_.rejit(getattr(ab, "py_func", ab), error_model="numpy")
    tag = f"standalone_{compile_.plant_tag(plant)}" if plant is not None else "standalone"
    ns["_PAB"] = plant_table.direct_binding(own_ab, tag=tag)
    opts = _opts()
    tpl = compile_.Template
    return compile_.Recipe(
        kind="standalone",
        plant=plant,
        bindings=ns,
        templates=(
            tpl("_SETUP", member._tpl_setup, opts),
            tpl("_DELAY_REFERENCE", _tpl_delay_reference, opts),
            tpl("_CTRL_INIT", _tpl_ctrl_init, opts),
            tpl("_CTRL_RUN", _tpl_ctrl_run, opts),
            tpl("_CTRL_STEP_EACH", _tpl_ctrl_step_each, opts),
        ),
        entry=tpl("_CTRL_STEP", _tpl_ctrl_step, opts),
        sources=_sources(),
        also_cached=("_SETUP", "_CTRL_INIT", "_CTRL_RUN", "_CTRL_STEP_EACH"),
    )


def _standalone(plant: Any = None) -> SimpleNamespace:
    """The compiled :func:`standalone_recipe` of ``plant`` (built once per process; loaded
    from the disk cache when it was compiled before)."""
    key = id(plant)
    with _LOCK:
        if key not in _STANDALONE or _STANDALONE[key][0] is not plant:
            space = compile_.build(standalone_recipe(plant), cache=cache_enabled()).namespace
            fns = SimpleNamespace(
                setup=space["_SETUP"],
                init=space["_CTRL_INIT"],
                step=space["_CTRL_STEP"],
                run=space["_CTRL_RUN"],
                step_each=space["_CTRL_STEP_EACH"],
            )
            _STANDALONE[key] = (plant, fns)
        return _STANDALONE[key][1]


class DiscreteController:
    """The engine's discrete controller, stepped from Python one sample at a time.

    The same compiled update the sampled engine runs (:func:`_tpl_ctrl_step`), with the
    coefficients of :func:`aiofl.engine.discrete.sampling_rows`.  One call per sample:
    :meth:`init` with the first measurement, then :meth:`step` with the reference (and its
    derivatives) and the measurement, returning u.

    Parameters
    ----------
    controller
        An AIOFL controller (LESO, INLESO, LADRC, ...); the IOFL law needs the plant state
        and is refused.
    sampling
        Sample time and discretisation.
    plant
        The plant whose nominal model a model-assisted observer (``eso.model =
        "nominal"``) carries, with its nominal parameters; not needed otherwise.
    x0
        The plant state the model-assisted observer's bandwidth gains are placed at, as the
        engine places them at the scenario's initial state:
        :math:`J = \\partial(\\hat\\alpha + \\hat\\beta u^*)/\\partial\\xi` at
        :math:`\\xi^* = \\Phi(x_0)` (:func:`aiofl.engine.observer_gains.model_jacobians`);
        empty (the default): the origin.  Not used otherwise.
    """

    def __init__(
        self,
        controller: Controller,
        sampling: Sampling,
        plant: Any = None,
        x0: Sequence[float] = (),
    ) -> None:
        if controller.law != "aiofl":
            raise ValueError(
                f"controller.law_kind = {controller.law!r}: a discrete controller without "
                "the plant needs the AIOFL law (the IOFL law evaluates the plant model)"
            )
        sampling.check(controller)
        if controller.eso_model != "none":
            if plant is None:
                raise ValueError(
                    f"controller.eso.model = {controller.eso_model!r}: the discrete controller "
                    "evaluates the plant's nominal model; pass plant="
                )
            controller.check_plant(plant)
        self.controller = controller
        self.sampling = sampling
        batch = controller_batch(controller)
        # a model-assisted observer's gain is placed for the model's error map at Φ(x0)
        jac = model_jacobians(plant, batch, [x0]) if controller.eso_model != "none" else None
        self.row = discrete_row(controller, sampling, jac)  # a failing Ts named, with its range
        self._fn = _standalone(plant if controller.eso_model != "none" else None)
        self._pn = plant.param_vector() if plant is not None else np.zeros(1)
        self._q = np.zeros(N_Q)
        self._iq = np.zeros(N_IQ, dtype=np.int64)
        self._fn.setup(batch.ints[0], batch.floats[0], self._q, self._iq)
        self._cs = np.zeros(N_CS)
        self._scr = np.zeros(N_CS)
        self._rr = np.zeros((1, L.RHO_MAX + 2))

    def init(self, y0: float) -> None:
        r"""Reset the states for the first measurement ``y0`` as ``controller.eso_init``
        says, as the continuous loop starts it: ``"zero"`` (the default: prediction 0, the
        differentiator at 0, ``y0`` unused), ``"output"`` (:math:`\hat\xi_1 = y_0`, the
        other states 0) or ``"bumpless"`` (that and the differentiator at rest at ``y0``;
        :meth:`reset`)."""
        self._fn.init(self._iq, self._q, self._cs, float(y0))

    def reset(self, y0: float, u0: float | None = None) -> None:
        r"""A bumpless (re)start at ``y0``, at any sample boundary, whatever the config's
        start: :math:`\hat\xi = (y_0, 0, ..., 0, -b_0 u_0)`, the differentiator at rest at
        ``y0``; a plant at rest at :math:`y_0 = r` gets :math:`u = u_0` next (the hand-over
        of a manual command ``u0``; None: the design's ``eso.u0``).  The model-assisted
        observer starts at its model's :math:`-\hat\alpha/\hat\beta` (``u0`` refused)."""
        iq = self._iq.copy()
        iq[IQ_EINIT] = L.ESO_INIT_BUMPLESS
        q = self._q.copy()
        if u0 is not None:
            q[L.F_ESO_U0] = check_number("u0", u0, finite=True)
            if u0 != 0.0 and self.controller.eso_model != "none":
                raise ValueError(f"u0 = {u0}: the model-assisted observer takes no u0")
        self._fn.init(iq, q, self._cs, float(y0))

    def _reference(self, r: float | Sequence[float] | NDArray[np.float64]) -> None:
        rv = np.atleast_1d(np.asarray(r, dtype=np.float64))
        self._rr[0, :] = 0.0
        self._rr[0, : rv.size] = rv

    def step(self, r: float | Sequence[float] | NDArray[np.float64], y: float) -> float:
        """One sample: ``r`` = r (or r, ṙ, ..., r^(ρ)) at t_k, ``y`` the measurement; returns u."""
        self._reference(r)
        return float(self._fn.step(*self._update_args(self._cs, y)))

    def _update_args(self, cs: NDArray[np.float64], y: float | NDArray[np.float64]) -> tuple:
        """The arguments of the compiled update up to the nominal parameters (the plant
        table is unread: α, β are called directly), from the controller state ``cs`` and
        the measurement(s) ``y``."""
        return (_NO_TABLE, self._iq, self._q, self.row, cs, self._scr, y, self._rr, 0, self._pn)

    def run(self, n: int, r: float | Sequence[float] | NDArray[np.float64], y: float) -> float:
        """``n`` samples (n ≥ 1) with the same reference ``r`` and measurement ``y`` in one
        compiled call (:meth:`step` n times); returns the last u.

        Parameters
        ----------
        n
            The number of samples, 1 ≤ n ≤ 1e9.
        r
            The reference, as for :meth:`step`.
        y
            The measurement.

        Returns
        -------
        float
        """
        if isinstance(n, bool) or not isinstance(n, int | np.integer) or not 1 <= n <= 10**9:
            raise ValueError(f"n = {n!r}; allowed: an integer, 1 <= n <= 1e9")
        self._reference(r)
        return float(self._fn.run(*self._update_args(self._cs, y), n))

    def step_each(
        self,
        states: NDArray[np.float64],
        r: float | Sequence[float] | NDArray[np.float64],
        ys: NDArray[np.float64],
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """One sample from each of several controller states (rows of ``states``, shape
        (K, len(state))) with the measurements ``ys`` (K,) and one reference ``r``:
        ``(next states, commands)``, as :meth:`step` from each (the controller's own
        state is left alone).  For finite-difference Jacobians of the update.

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
