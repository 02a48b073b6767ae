r"""The discrete controller's update compiled without a plant: what
:class:`aiofl.discrete_controller.DiscreteController` steps from Python.

The sampled engine's controller update (:func:`aiofl.engine.kernel.sampled._tpl_ctrl_step`, its
start, its per-member setup and its n-step and each-state variants) compiled without the
plant's dynamics (:func:`update_recipe`), built once per process and plant
(:func:`compiled_update`; loaded from the disk cache when it was compiled before).  A
model-assisted observer (``eso.model = "nominal"``) binds the plant's nominal
``alpha_beta_of_xi``; every other controller shares the update compiled without a plant.

The compiled functions take the controller's packed constants (:func:`member_constants`),
its discrete coefficient row (:func:`aiofl.engine.sample_time.discrete_row`), its state
``cs`` (:data:`aiofl.engine.kernel.sampled.N_CS` values) and a scratch row, the measurement, the
reference row ``rr`` (r, r', ..., one row of ``RHO_MAX + 2``) and the nominal parameters;
the plant table argument is unread (:data:`NO_TABLE`).  :func:`compile_ahead` compiles (or
loads) every entry for the argument types of every controller without a plant model
(``python -m aiofl.engine.build.prepare PLANT dc``).
"""

from __future__ import annotations

import sys
import threading
from types import SimpleNamespace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from aiofl import layout as L
from aiofl.cache import cache_enabled
from aiofl.controller import Controller, controller_batch
from aiofl.engine import discrete_rows
from aiofl.engine.build import bindings, plant_table
from aiofl.engine.build import compile as compile_
from aiofl.engine.kernel import member, plant_calls, sampled
from aiofl.engine.kernel.member import N_IQ, N_Q
from aiofl.engine.kernel.plant_calls import N_TABLE
from aiofl.engine.kernel.sampled import N_CS

__all__ = ["NO_TABLE", "compile_ahead", "compiled_update", "member_constants", "update_recipe"]

_LOCK = threading.Lock()
_COMPILED: dict[int, tuple[Any, SimpleNamespace]] = {}

NO_TABLE = np.zeros(N_TABLE, dtype=np.int64)
"""The plant table the update is passed: unread (its α, β are called directly)."""


def update_recipe(plant: Any = None) -> compile_.Recipe:
    """The recipe of the controller update compiled without the plant's dynamics: the
    per-member setup, the start, the step, n steps at one measurement and one step from
    each of several states, each cached on disk; given ``plant``, with its nominal normal
    form ``alpha_beta_of_xi`` for the model-assisted observer.

    Parameters
    ----------
    plant
        The plant whose ``alpha_beta_of_xi`` a model-assisted observer calls (None: no
        model).

    Returns
    -------
    Recipe
    """
    from aiofl.components.fastmath import FASTMATH
    from aiofl.plants.base import _no_alpha_beta

    # private copies of every compiled function it calls, as the loops' recipes bind: the
    # public ones are cached by numba beside their own source only, so a cached update
    # could link a stale callee (bindings.private_components)
    ns = compile_.template_globals(member)
    bindings.bind_private(ns)
    ns.update(_N=1, _NZ=1, **bindings.component_functions())
    bindings.bind_discrete(ns, bindings.private_components()["discrete"])
    ab = plant.compiled[5] if plant is not None else _no_alpha_beta
    # the plant's α, β called directly (its table argument unread: NO_TABLE)
    own_ab = compile_.rejit(getattr(ab, "py_func", ab), error_model="numpy")
    tag = f"standalone_{compile_.plant_tag(plant)}" if plant is not None else "standalone"
    ns["_PAB"] = plant_table.direct_binding(own_ab, tag=tag)
    opts = {"fastmath": FASTMATH, "error_model": "numpy"}
    tpl = compile_.Template
    here = sys.modules[__name__].__file__
    return compile_.Recipe(
        kind="standalone",
        plant=plant,
        bindings=ns,
        templates=(
            tpl("_SETUP", member._tpl_setup, opts),
            tpl("_DELAY_REFERENCE", sampled._tpl_delay_reference, opts),
            tpl("_CTRL_INIT", sampled._tpl_ctrl_init, opts),
            tpl("_CTRL_RUN", sampled._tpl_ctrl_run, opts),
            tpl("_CTRL_STEP_EACH", sampled._tpl_ctrl_step_each, opts),
        ),
        entry=tpl("_CTRL_STEP", sampled._tpl_ctrl_step, opts),
        # every kernel's sources, the templates', the plant calls' (its α, β binding), the
        # discrete coefficient rows' and this recipe's
        sources=(
            *bindings.engine_sources(),
            sampled.__file__,
            plant_calls.__file__,
            plant_table.__file__,
            discrete_rows.__file__,
            here,
        ),
        also_cached=("_SETUP", "_CTRL_INIT", "_CTRL_RUN", "_CTRL_STEP_EACH"),
    )


def compiled_update(plant: Any = None) -> SimpleNamespace:
    """The compiled :func:`update_recipe` of ``plant`` (built once per process; loaded from
    the disk cache when it was compiled before): ``setup``, ``init``, ``step``, ``run`` and
    ``step_each``.

    Parameters
    ----------
    plant
        As for :func:`update_recipe`.

    Returns
    -------
    SimpleNamespace
    """
    key = id(plant)
    with _LOCK:
        if key not in _COMPILED or _COMPILED[key][0] is not plant:
            space = compile_.build(update_recipe(plant), cache=cache_enabled()).namespace
            fns = SimpleNamespace(
                setup=space["_SETUP"],
                init=space["_CTRL_INIT"],
                step=space["_CTRL_STEP"],
                run=space["_CTRL_RUN"],
                step_each=space["_CTRL_STEP_EACH"],
            )
            _COMPILED[key] = (plant, fns)
        return _COMPILED[key][1]


def member_constants(
    update: SimpleNamespace, controller: Controller
) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """``controller``'s packed constants ``(q, iq)`` as the update reads them (the
    per-member setup of :mod:`aiofl.engine.kernel.member`, run by ``update.setup``).

    Parameters
    ----------
    update
        The compiled update (:func:`compiled_update`).
    controller
        The controller.

    Returns
    -------
    q, iq : ndarray
    """
    batch = controller_batch(controller)
    q = np.zeros(N_Q)
    iq = np.zeros(N_IQ, dtype=np.int64)
    update.setup(batch.ints[0], batch.floats[0], q, iq)
    return q, iq


def compile_ahead() -> None:
    """Compile (or load) every entry of the update without a plant (setup, start, step, n
    steps, one step from each of several states) by stepping a plain LADRC once through
    each: the argument types are those of every controller without a plant model."""
    from aiofl.engine.discrete_rows import Sampling, sampling_rows

    values = {"eso.omega0": 10.0, "sef.omega_c": 2.0, "td.omega": 5.0, "law.b0": 1.0}
    ladrc = Controller.from_structure("LADRC", rho=1, values=values)
    update = compiled_update(None)
    q, iq = member_constants(update, ladrc)
    row = sampling_rows(controller_batch(ladrc), [Sampling(1e-3)], 1e-3)[0]
    cs, scr = np.zeros(N_CS), np.zeros(N_CS)
    rr = np.zeros((1, L.RHO_MAX + 2))
    pn = np.zeros(1)
    update.init(iq, q, cs, 0.0)
    update.step(NO_TABLE, iq, q, row, cs, scr, 0.0, rr, 0, pn)
    update.run(NO_TABLE, iq, q, row, cs, scr, 0.0, rr, 0, pn, 1)
    us = np.empty(1)
    update.step_each(NO_TABLE, iq, q, row, cs[None, :].copy(), scr, np.zeros(1), rr, 0, pn, us)
