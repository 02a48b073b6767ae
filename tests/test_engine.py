"""The compiled engine: against an independent scipy path, convergence order, the ESO it
integrates, determinism, batching, divergence handling and plant errors."""

from __future__ import annotations

import dataclasses
import math
import re

import numba
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from aiofl.config import load_config
from aiofl.controller import Controller, controller_batch
from aiofl.engine.build import instances
from aiofl.engine.reference import closed_loop, reference_simulate, setup_loop
from aiofl.engine.simulation import closed_loop_rhs, simulate, simulate_batch
from aiofl.plants import get_plant
from aiofl.plants.base import Plant, PlantError
from aiofl.scenario import Reference, Scenario, noise_sequence
from chain_plant import chain3
from reachable import reachable_compiled

BETA_SLFJM = 1.61 * 0.00767 * 70.0 / (0.0059 * 0.0021 * 2.6)  # Ks Km Kg / (Jl Jh Rm)


def smooth_controller(**values: float) -> Controller:
    """Linear ESO + linear prefilter + full-state linear SEF (an LADRC), moderate gains:
    a smooth, non-stiff loop on the SLFJM that an adaptive solver integrates easily."""
    vals = {
        "law.b0": BETA_SLFJM,
        "eso.omega0": 100.0,
        "sef.omega_c": 10.0,
        "td.omega": 20.0,
        **values,
    }
    return Controller.from_structure("LADRC", n_feedback=4, values=vals).with_binomial_alphas()


@pytest.fixture(scope="module")
def slfjm() -> Plant:
    return get_plant("slfjm")


# ------------------------------------------------------------ engine vs scipy solve_ivp
@pytest.mark.parametrize(
    "scenario",
    [
        Scenario(t_final=2.0),
        Scenario(
            t_final=2.0,
            disturbance_amplitude=0.5,
            disturbance_time=1.0,
            plant_scale={"J_l": 1.4},
            parameter_change_time=0.5,
            x0=(0.1, -0.05, 0.0, 0.2),
        ),
        Scenario(t_final=1.0, reference=Reference(kind="step", amplitude=0.5, t_step=0.25)),
    ],
    ids=["sine", "disturbance+J_l*1.4+x0", "step"],
)
def test_engine_agrees_with_scipy_on_a_smooth_loop(slfjm, scenario):
    """RK4 at dt = 1e-4 and RK45 at rtol 1e-10 give the same trajectory and metrics."""
    ctrl = smooth_controller()
    eng = simulate(slfjm, ctrl, scenario, dt=1e-4, decimation=100)
    ref = reference_simulate(slfjm, ctrl, scenario, t_eval=eng.t, rtol=1e-10, atol=1e-12)
    assert not eng.failed
    np.testing.assert_allclose(eng["y"], ref.y, rtol=0, atol=1e-9)
    np.testing.assert_allclose(eng["u"], ref.u, rtol=1e-7, atol=1e-7 * np.max(np.abs(ref.u)))
    for i in range(4):
        np.testing.assert_allclose(eng[f"x{i + 1}"], ref.x[:, i], atol=1e-8)
    for i in range(5):
        scale = np.max(np.abs(ref.xi[:, i]))
        np.testing.assert_allclose(eng[f"xi_hat{i + 1}"], ref.xi[:, i], atol=1e-7 * scale)
    # ISE, ISU have smooth integrands (RK4-accurate); |y - r| and |u| have kinks at their
    # zero crossings, where a fixed-step integral is only second order
    for name, rel in (("ise", 1e-7), ("isu", 1e-7), ("itae", 1e-5), ("iae", 1e-5), ("iau", 1e-5)):
        assert eng.metrics[name] == pytest.approx(ref.metrics[name], rel=rel), name


def test_engine_agrees_with_scipy_on_the_paper_inleso_loop(slfjm):
    """The nonlinear path (INLESO, INLSEF, ITD, printed parameters) over its first second,
    J_l change and disturbance included: RK4 at dt = 1e-5 vs RK45 at rtol 1e-8."""
    rc = load_config("paper-s2-inleso")
    sc = dataclasses.replace(
        rc.scenario, t_final=1.0, disturbance_time=0.5, parameter_change_time=0.25
    )
    eng = simulate(slfjm, rc.controller, sc, dt=1e-5, decimation=1000)
    ref = reference_simulate(slfjm, rc.controller, sc, t_eval=eng.t, rtol=1e-8, atol=1e-10)
    np.testing.assert_allclose(eng["y"], ref.y, atol=1e-6)
    for name in ("itae", "isu", "iau"):
        assert eng.metrics[name] == pytest.approx(ref.metrics[name], rel=1e-5), name


# ---------------------------------------------- the compiled F(t, z) vs the oracle's F
_KINDS = [
    (eso, td, sef)
    for eso in ("linear", "improved")
    for td in ("exact", "han", "improved", "linear")
    for sef in ("nonlinear", "improved", "linear")
]


@pytest.mark.slow  # compiles the engine's single-evaluation entry point (~5 s) on first use
@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(kinds=st.sampled_from(_KINDS), seed=st.integers(0, 2**32 - 1))
def test_compiled_rhs_equals_the_oracle_rhs(kinds, seed):
    """Every component combination: the engine's dz equals the plain-Python F(t, z) of
    aiofl.engine.reference at a random state, to rounding."""
    eso, td, sef = kinds
    rng = np.random.default_rng(seed)
    m = int(rng.integers(1, 3)) if td in ("han", "improved") else int(rng.integers(1, 5))
    vals = {
        "law.b0": rng.uniform(1, 1e4),
        "law.u_max": rng.choice([math.inf, rng.uniform(0.1, 5)]),
        "eso.omega0": rng.uniform(5, 500),
        **{f"eso.alpha{i}": rng.uniform(0, 10) for i in range(1, 6)},
        "eso.k_alpha": rng.uniform(0, 2),
        "eso.k_beta": rng.choice([0.0, rng.uniform(0, 2)]),
        "eso.g_alpha": rng.choice([1.0, rng.uniform(0.1, 2)]),
        "eso.g_beta": rng.choice([0.0, 1.0, rng.uniform(0, 2)]),
        "td.R": rng.uniform(1, 1e3),
        "td.a": rng.uniform(0, 0.99),
        "td.b": rng.uniform(0.1, 10),
        "td.c": rng.uniform(0.05, 2),
        "td.rho": rng.uniform(1, 50),
        "td.omega": rng.uniform(1, 50),
        "sef.omega_c": rng.uniform(1, 30),
        "sef.v_limit": rng.uniform(0.1, 10),
        **{f"sef.k{i}": rng.uniform(-5, 5) for i in range(1, 5)},
        **{f"sef.kb{i}": rng.choice([0.0, rng.uniform(0, 5)]) for i in range(1, 5)},
        **{f"sef.mu{i}": rng.uniform(0, 20) for i in range(1, 5)},
        **{f"sef.alpha{i}": rng.choice([1.0, rng.uniform(0.1, 2)]) for i in range(1, 5)},
        **{f"sef.delta{i}": rng.uniform(0.01, 3) for i in range(1, 5)},
    }
    ctrl = Controller(eso=eso, td=td, sef=sef, rho=4, n_feedback=m, values=vals)
    plant = get_plant("slfjm")
    scen = Scenario(
        reference=Reference(amplitude=rng.uniform(0.1, 1), omega=rng.uniform(0.5, 5)),
        disturbance_amplitude=rng.uniform(-1, 1),
        disturbance_time=0.0,
        plant_scale={"J_l": 1.4},
    )
    s = setup_loop(plant, ctrl, scen)
    x = rng.normal(0, 1, 4)
    tdv = rng.normal(0, 1, s.n_td)
    xi = rng.normal(0, 1, 5) * np.array([1, 3, 10, 30, 100])
    t = float(rng.uniform(0, 20))
    noise = float(rng.normal(0, 0.01))
    got = closed_loop_rhs(plant, ctrl, scen, t, x, tdv, xi, noise=noise, changed=True)
    z = np.concatenate([x, tdv, xi, np.zeros(5)])
    dz, sig = closed_loop(
        s, t, z, disturbance=scen.disturbance_amplitude, plant_params=s.p_changed,
        noise=noise, step_on=True,
    )  # fmt: skip
    want = np.concatenate([dz[:4], dz[4 : 4 + s.n_td], dz[4 + s.n_td : -5]])
    have = np.concatenate([got["dx"], got["dtd"], got["dxi"]])
    np.testing.assert_allclose(have, want, rtol=1e-11, atol=1e-11 * (1 + np.max(np.abs(want))))
    np.testing.assert_allclose(got["dmetrics"], dz[-5:], rtol=1e-11, atol=1e-300)
    for key in ("r", "y", "y_meas", "u", "d"):
        assert got[key] == pytest.approx(sig[key], rel=1e-11, abs=1e-12), key


def test_compiled_rhs_of_the_iofl_law_equals_the_oracle(slfjm):
    rc = load_config("iofl-s2")
    s = setup_loop(slfjm, rc.controller, rc.scenario)
    rng = np.random.default_rng(5)
    for _ in range(5):
        x = rng.normal(0, 0.5, 4)
        xi = rng.normal(0, 1, 5)
        got = closed_loop_rhs(slfjm, rc.controller, rc.scenario, 3.0, x, (), xi)
        dz, sig = closed_loop(
            s, 3.0, np.concatenate([x, xi, np.zeros(5)]), disturbance=0.0,
            plant_params=s.p_nominal, noise=0.0, step_on=True,
        )  # fmt: skip
        np.testing.assert_allclose(got["dx"], dz[:4], rtol=1e-11, atol=1e-9)
        assert got["u"] == pytest.approx(sig["u"], rel=1e-11)


def test_engine_fal_is_continuous_at_delta(slfjm):
    """The engine's fal (aiofl.components.feedback.fal_scaled with the precomputed δ^(α-1)) is
    continuous at |e1| = δ1: u on both sides of the kink differs by O(ε)."""
    rc = load_config("paper-s1-leso")
    delta1 = rc.controller.value("sef.delta1")
    us = []
    for side in (1.0, -1.0):
        for eps in (-1e-10, 1e-10):
            # e1 = r1 - ξ̂1 = side·δ1·(1 + eps), e2 = 0
            xi1 = -side * delta1 * (1.0 + eps)
            got = closed_loop_rhs(slfjm, rc.controller, rc.scenario, 0.0, np.zeros(4),
                                  (0.0, 0.0), (xi1, 0.0, 0.0, 0.0, 0.0))  # fmt: skip
            us.append(got["u"])
        assert us[-1] == pytest.approx(us[-2], rel=1e-8)
        assert us[-1] == pytest.approx(side * delta1 ** rc.controller.value("sef.alpha1"))


def test_kernel_links_no_component_from_numbas_per_function_cache(slfjm):
    """numba keys a ``cache=True`` function's disk cache on its own file only, so a cached
    ``feedback.linear_sef_gain`` keeps an old ``fastmath.binomial_power`` linked in after
    fastmath.py is edited; a kernel compiled against it was then stored under the new
    fingerprint and differed from a fresh compile of the same source (by rounding, in the
    exact-TD designs).  Nothing the kernel calls may come from such a cache, and the
    private copies it calls compute bitwise what the public components do."""
    from aiofl.components import differentiators, fastmath, feedback, law, observers

    # the sampled instance binds every component, the law dispatch and the discrete update;
    # the scalar variant keeps the components' own flags and libm (bitwise the public ones)
    ns = dict(instances.recipe(slfjm, 1, sampled_data=True, variant="scalar").bindings)
    from numba.core.dispatcher import Dispatcher

    found = [d for d in reachable_compiled(ns) if isinstance(d, Dispatcher)]
    component = [d for d in found if d.py_func.__module__.startswith("aiofl.components.")]
    names = {d.py_func.__name__ for d in component}
    # the kernel's own functions, the components it binds and what they call across modules
    assert {"fal_scaled", "linear_sef_gain", "binomial_power", "abspow", "aiofl_law"} <= names
    assert any(d.py_func.__name__ == "_aiofl_command" for d in found)
    for d in found:
        if d.py_func.__module__.startswith(("aiofl.components.", "aiofl.engine.kernel.member")):
            assert type(d._cache).__name__ == "NullCache", d.py_func.__qualname__
    for public in (fastmath, feedback, observers, differentiators, law):
        assert not any(d is v for d in found for v in vars(public).values())
    # same code, same flags: the same numbers
    for i in range(1, 5):
        assert ns["_LINEAR_SEF_GAIN"](4, i, 17.3) == feedback.linear_sef_gain(4, i, 17.3)
    for e in (-0.7, -1e-3, 0.0, 2e-4, 0.31, 5.0):
        args = (e, 0.5, 0.01, feedback.fal_inner_slope(0.5, 0.01))
        assert ns["_FAL"](*args) == feedback.fal_scaled(*args)
        assert ns["_INLSEF_TERM"](e, 3.0, 2.0, 1.5, 0.7) == feedback.inlsef_term(
            e, 3.0, 2.0, 1.5, 0.7
        )


def test_no_public_component_that_calls_another_module_is_disk_cached():
    """The analysis, the C export and the sampled kernel call the public component functions;
    one cached by numba would keep an edited callee's old code (numba keys its cache on the
    caller's file only).  Every public component function that names a compiled function of
    another module is uncached; the leaves may be cached."""
    import importlib
    import pkgutil

    from numba.core.dispatcher import Dispatcher

    import aiofl.components as comp

    callers, leaves = [], []
    for info in pkgutil.iter_modules(comp.__path__):
        mod = importlib.import_module(f"aiofl.components.{info.name}")
        for obj in vars(mod).values():
            if not isinstance(obj, Dispatcher) or obj.py_func.__module__ != mod.__name__:
                continue
            names = obj.py_func.__code__.co_names
            foreign = [
                n
                for n in names
                if isinstance(g := obj.py_func.__globals__.get(n), Dispatcher)
                and g.py_func.__module__ != mod.__name__
            ]
            (callers if foreign else leaves).append(obj)
            if foreign:
                assert type(obj._cache).__name__ == "NullCache", obj.py_func.__qualname__
    names = {d.py_func.__name__ for d in callers}
    assert {"fal_scaled", "inlsef_term", "linear_sef_gain", "improved_td_rhs_scaled"} <= names
    assert any(type(d._cache).__name__ != "NullCache" for d in leaves)  # the check can fail


# ------------------------------------------------------------------ convergence order
def _max_error(plant, ctrl, scen, dt, method, ref):
    res = simulate(plant, ctrl, scen, dt=dt, method=method, decimation=round(8e-3 / dt))
    return np.max(np.abs(res["y"] - ref["y"])), abs(res.metrics["isu"] - ref.metrics["isu"])


def test_rk4_error_falls_16x_when_dt_halves(slfjm):
    ctrl, scen = smooth_controller(), Scenario(t_final=1.0)
    ref = simulate(slfjm, ctrl, scen, dt=1.25e-4, decimation=64)
    e1, i1 = _max_error(slfjm, ctrl, scen, 2e-3, "rk4", ref)
    e2, i2 = _max_error(slfjm, ctrl, scen, 1e-3, "rk4", ref)
    assert 12.0 <= e1 / e2 <= 20.0
    assert 12.0 <= i1 / i2 <= 20.0


def test_euler_error_falls_2x_when_dt_halves(slfjm):
    ctrl, scen = smooth_controller(), Scenario(t_final=1.0)
    ref = simulate(slfjm, ctrl, scen, dt=6.25e-5, method="euler", decimation=128)
    e1, i1 = _max_error(slfjm, ctrl, scen, 1e-3, "euler", ref)
    e2, i2 = _max_error(slfjm, ctrl, scen, 5e-4, "euler", ref)
    assert 1.7 <= e1 / e2 <= 2.5
    assert 1.7 <= i1 / i2 <= 2.5


# ---------------------------------------------------------- the ESO the engine integrates
CHAIN = chain3(2.0, 0.5, 3.0)
"""d³x1/dt³ = -a sin x1 - c x1'' + b u (tests/chain_plant.py): already a chain of 3
integrators."""


@pytest.mark.slow  # the chain plant's kernel (shared with test_api_traps), unless cached
def test_eso_estimates_states_and_total_disturbance():
    """On a plant that *is* a chain of ρ = 3 integrators, ξ̂_i → x_i and ξ̂_4 → the total
    disturbance f_T = -a sin x1 - c x3 + (b - b0) u, with errors shrinking like
    ω0^-(ρ+2-i) (the linear ESO's error transfer functions): 16x, 8x, 4x, 2x when ω0
    doubles."""
    scen = Scenario(t_final=4.0, reference=Reference(amplitude=0.5, omega=1.5))
    errs = []
    for omega0 in (40.0, 80.0):
        ctrl = Controller.from_structure(
            "LADRC",
            rho=3,
            n_feedback=3,
            values={"law.b0": 2.0, "eso.omega0": omega0, "sef.omega_c": 4.0, "td.omega": 8.0},
        ).with_binomial_alphas()
        res = simulate(CHAIN, ctrl, scen, decimation=10)
        late = res.t > 1.5
        x = [res[f"x{i}"][late] for i in (1, 2, 3)]
        f_total = -2.0 * np.sin(x[0]) - 0.5 * x[2] + (3.0 - 2.0) * res["u"][late]
        truth = [*x, f_total]
        errs.append(
            [
                np.max(np.abs(res[f"xi_hat{i + 1}"][late] - truth[i])) / np.max(np.abs(truth[i]))
                for i in range(4)
            ]
        )
    lo, hi = errs
    assert hi[0] < 1e-6 and hi[1] < 1e-4 and hi[2] < 2e-3 and hi[3] < 0.15
    for i in range(4):
        assert 0.7 * 2 ** (4 - i) <= lo[i] / hi[i] <= 1.4 * 2 ** (4 - i)


# ------------------------------------------------------------ determinism and batches
def _noisy(seed: int, t_final: float = 1.0) -> Scenario:
    return Scenario(t_final=t_final, noise_variance=1e-4, noise_hold=1e-3, noise_seed=seed)


def test_same_seed_same_noise_and_numbers_different_seed_differs(slfjm):
    ctrl = smooth_controller()
    a = simulate(slfjm, ctrl, _noisy(7), decimation=1)
    b = simulate(slfjm, ctrl, _noisy(7), decimation=1)
    c = simulate(slfjm, ctrl, _noisy(8), decimation=1)
    assert a.metrics == b.metrics
    np.testing.assert_array_equal(a["y_meas"], b["y_meas"])
    assert a.metrics["itae"] != c.metrics["itae"]
    assert np.any(a["y_meas"] != c["y_meas"])
    np.testing.assert_array_equal(noise_sequence(7, 100), noise_sequence(7, 100))
    # y_meas - y is the seeded sequence, scaled by sqrt(variance), held over each 1 ms
    idx = np.floor(a.t / 1e-3 + 1e-9).astype(int)
    expected = 1e-2 * noise_sequence(7, idx.max() + 1)[idx]
    np.testing.assert_allclose(a["y_meas"] - a["y"], expected, rtol=0, atol=1e-15)
    assert np.std(expected) == pytest.approx(1e-2, rel=0.1)


def test_batch_members_equal_single_runs_bitwise_with_a_diverging_member(slfjm):
    """A batch of different controllers and scenarios (one diverges at ≈0.6 s) gives each
    member exactly its single-run numbers; the diverged member is reported with its time
    and stops, the others carry on to the end; thread count does not matter."""
    horizon = 1.0
    confs = [load_config(n) for n in ("paper-s1-leso", "paper-s1-inleso", "paper-s3-inleso")]
    ctrls = [c.controller for c in confs] + [
        smooth_controller(),
        smooth_controller(**{"eso.omega0": 60.0}),
    ]
    scens = [dataclasses.replace(c.scenario, t_final=horizon) for c in confs]
    scens += [Scenario(t_final=horizon), _noisy(3, horizon)]
    singles = [simulate(slfjm, c, s, decimation=20) for c, s in zip(ctrls, scens, strict=True)]
    old = numba.get_num_threads()
    try:
        for threads in sorted({1, old}):
            numba.set_num_threads(threads)
            batch = simulate_batch(slfjm, ctrls, scens, store=True, decimation=20)
            for i, single in enumerate(singles):
                member = batch.member(i)
                assert member.metrics == single.metrics
                assert member.failed == single.failed
                assert member.stopped_at == single.stopped_at
                np.testing.assert_array_equal(member.t, single.t)
                for key, sig in single.signals.items():
                    np.testing.assert_array_equal(member.signals[key], sig)
    finally:
        numba.set_num_threads(old)
    div = singles[2]
    # paper-s3-inleso, printed parameters: lost when |y - r| passes the default envelope,
    # ten times max |r| (its numbers diverged at 0.6 s), its last point stored there
    assert div.status == "lost" and div.failed and div.metrics is None
    assert 0.42 < div.stopped_at < 0.43
    assert div.t[-1] == pytest.approx(div.stopped_at, abs=1e-12)
    assert all(
        not s.failed and s.t[-1] == pytest.approx(horizon) for i, s in enumerate(singles) if i != 2
    )
    assert np.isnan(batch.metric("itae")[2]) and np.isnan(batch.opi()[2])
    assert np.all(np.isfinite(np.delete(batch.opi(), 2)))


def test_population_batch_equals_single_runs(slfjm):
    """A GA-style population (one controller, a column varied) member by member."""
    ctrl = smooth_controller()
    omegas = np.array([30.0, 80.0, 150.0, 5.0])
    batch = simulate_batch(
        slfjm, controller_batch(ctrl, {"eso.omega0": omegas}), Scenario(t_final=0.5)
    )
    for i, w in enumerate(omegas):
        single = simulate(slfjm, ctrl.with_values(**{"eso.omega0": w}), Scenario(t_final=0.5))
        np.testing.assert_array_equal(batch.metrics[i], [single.metrics[k] for k in
                                      ("itae", "iae", "ise", "isu", "iau")])  # fmt: skip


def test_divergence_is_data_and_the_threshold_is_honoured(slfjm):
    bad = smooth_controller(**{"law.b0": 1.0})  # b0 far below β: the loop explodes
    res = simulate(slfjm, bad, Scenario(t_final=1.0), decimation=1)
    assert res.failed and res.metrics is None and res.opi() is None
    assert 0.0 < res.stopped_at < 1.0
    assert np.all(np.isfinite(res["y"]))
    late = simulate(slfjm, bad, Scenario(t_final=1.0), divergence_threshold=1e30)
    assert late.stopped_at >= res.stopped_at


def test_store_and_decimation_do_not_change_numbers(slfjm):
    ctrl, scen = smooth_controller(), Scenario(t_final=0.5)
    full = simulate(slfjm, ctrl, scen, decimation=1)
    tenth = simulate(slfjm, ctrl, scen, decimation=10)
    bare = simulate_batch(slfjm, ctrl, scen, store=False)
    assert full.metrics == tenth.metrics
    np.testing.assert_array_equal(bare.metrics[0], list(full.metrics.values()))
    assert bare.trajectories is None
    for key in ("y", "u", "xi_hat5", "r1"):
        np.testing.assert_array_equal(tenth[key], full[key][::10])
    assert full.t[-1] == pytest.approx(0.5) and len(full.t) == 5001


def test_exact_td_stores_the_analytic_reference_derivatives(slfjm):
    vals = {"law.b0": BETA_SLFJM, "eso.omega0": 100.0, "sef.omega_c": 10.0}
    ctrl = Controller(eso="linear", td="exact", sef="linear", rho=4, n_feedback=4, values=vals)
    ref = Reference(amplitude=0.7, omega=2.0, phase=0.3, offset=0.1)
    res = simulate(slfjm, ctrl.with_binomial_alphas(), Scenario(t_final=1.0, reference=ref))
    ph = 2.0 * res.t + 0.3
    expected = [0.7 * np.sin(ph) + 0.1, 1.4 * np.cos(ph), -2.8 * np.sin(ph), -5.6 * np.cos(ph)]
    for i, e in enumerate(expected):
        np.testing.assert_allclose(res[f"r{i + 1}"], e, atol=1e-12)
    np.testing.assert_allclose(res["r"], expected[0], atol=1e-15)


def test_disturbance_signal_and_parameter_change(slfjm):
    scen = Scenario(t_final=1.0, disturbance_amplitude=0.5, disturbance_time=0.5)
    res = simulate(slfjm, smooth_controller(), scen, decimation=1)
    assert np.all(res["d"][res.t < 0.5 - 1e-9] == 0.0)
    assert np.all(res["d"][res.t >= 0.5 - 1e-9] == 0.5)
    nominal = simulate(slfjm, smooth_controller(), Scenario(t_final=1.0), decimation=1)
    before = res.t < 0.5 - 1e-9
    np.testing.assert_array_equal(res["y"][before], nominal["y"][before])
    assert np.max(np.abs(res["y"] - nominal["y"])) > 1e-4


# ------------------------------------------------------------------------ plant errors
def _wrong_length_f(x, p):
    return (x[1], 0.0, 0.0)


def _int_entries_g(x, p):
    return (0, 0, 1, -1)


def _vector_h(x, p):
    return (x[0], x[1])


def _ok_f(x, p):
    return (x[2], x[3], 0.0, 0.0)


def _ok_g(x, p):
    return (0.0, 0.0, 1.0, -1.0)


def _ok_h(x, p):
    return x[0] + x[1]


@pytest.mark.parametrize(
    ("funcs", "name"),
    [
        ((_wrong_length_f, _ok_g, _ok_h), "f(x, p)"),
        ((_ok_f, _int_entries_g, _ok_h), "g(x, p)"),
        ((_ok_f, _ok_g, _vector_h), "h(x, p)"),
    ],
)
def test_a_plant_function_of_the_wrong_shape_raises_plant_error_naming_it(funcs, name):
    f, g, h = funcs
    bad = Plant(name="bad", n_states=4, f=f, g=g, h=h, params={"k": 1.0})
    with pytest.raises(PlantError, match=re.escape(name)):
        simulate(bad, smooth_controller(), Scenario(t_final=0.01))
    with pytest.raises(PlantError, match="bad"):
        bad.check()


def test_plant_that_is_not_callable_is_rejected():
    with pytest.raises(PlantError, match="f must be a function"):
        Plant(name="x", n_states=1, f=3.0, g=_ok_g, h=_ok_h, params={})  # type: ignore[arg-type]
