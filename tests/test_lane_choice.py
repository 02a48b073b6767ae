"""When a batch runs in lanes (aiofl.engine.build.lane_choice): the lane instance at hand, or
worth its compile by the rent rule; otherwise its members run alone, with the same numbers.

The plants here are fresh copies of a library plant (a new object: no instance of it is
built in this process), and no test compiles a lane instance.
"""

from __future__ import annotations

import dataclasses

import numba
import numpy as np
import pytest

from aiofl.cache import subdir
from aiofl.controller import Controller
from aiofl.engine import simulation
from aiofl.engine.build import compile as compile_
from aiofl.engine.build import instances, lane_choice
from aiofl.engine.kernel import loop
from aiofl.engine.simulation import simulate_batch
from aiofl.plants import get_plant
from aiofl.scenario import Reference, Scenario

WIDTH = loop.WIDTH


@pytest.fixture
def fresh():
    """A pendulum no instance was built for."""
    return dataclasses.replace(get_plant("pendulum"))


def _members(n: int) -> tuple[list[Controller], Scenario]:
    values = {"eso.omega0": 30.0, "sef.omega_c": 4.0, "td.omega": 8.0, "law.b0": 4.0}
    base = Controller.from_structure("LADRC", rho=2, values=values)
    ctrls = [base.with_values(**{"eso.omega0": 30.0 + k}) for k in range(n)]
    return ctrls, Scenario(t_final=0.05, reference=Reference(amplitude=0.5, omega=1.0))


def test_a_stored_kernel_of_todays_code_is_at_hand_one_of_older_code_is_not(
    fresh, tmp_path, monkeypatch
):
    """The disk check looks for the index file named after the recipe's kind, the plant's
    key and the fingerprint of today's code; a file of another fingerprint (older code, to
    be compiled again) does not count, nor does the other timing's (an empty cache)."""
    monkeypatch.setenv("AIOFL_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.delenv("AIOFL_NO_CACHE", raising=False)
    plant = fresh
    assert not lane_choice.lanes_at_hand(plant, False)
    rec = instances.recipe(plant, WIDTH)
    fp = compile_.fingerprint(rec)
    assert fp is not None
    folder = subdir("kernels")
    assert folder is not None
    start = compile_._cache_file_start(loop._tpl_loop, f"{rec.kind}_{compile_.plant_key(plant)}_")
    (folder / f"{start}{'0' * len(fp)}.nbi").write_bytes(b"")  # an older fingerprint
    assert not lane_choice.lanes_at_hand(plant, False)
    (folder / f"{start}{fp}.nbi").write_bytes(b"")
    assert lane_choice.lanes_at_hand(plant, False)
    assert not lane_choice.lanes_at_hand(plant, True)  # the sampled instance is not stored


def test_a_lane_instance_another_process_is_compiling_is_at_hand(fresh, tmp_path, monkeypatch):
    """Its compile lock held (here by another open file, as another process holds it):
    waiting for it costs less than renting beside it; the lock released and no kernel
    stored (the compile failed), it is not."""
    import fcntl

    monkeypatch.setenv("AIOFL_CACHE_DIR", str(tmp_path / "cache"))
    plant = fresh
    rec = instances.recipe(plant, WIDTH, sampled_data=True)
    fp = compile_.fingerprint(rec)
    folder = subdir("kernels")
    assert folder is not None and fp is not None
    name = f"{rec.kind}_{compile_.plant_key(plant)}_{fp}"
    lock = folder / f"{compile_._cache_file_start(loop._tpl_loop, name)}-k.py311.lock"
    with lock.open("a+b") as held:
        fcntl.flock(held, fcntl.LOCK_EX)
        assert lane_choice.lanes_at_hand(plant, True)
        assert not lane_choice.lanes_at_hand(plant, False)
    assert not lane_choice.lanes_at_hand(plant, True)


def test_the_rent_is_paid_until_it_reaches_the_compile_then_the_lanes_are_bought(
    fresh, tmp_path, monkeypatch
):
    """Steps below the price run alone and add to the plant's rent; the batch that brings
    the rent to the price runs in lanes and clears it; a batch worth the compile alone
    buys at once; each plant and timing pays its own rent (an empty cache: nothing at
    hand)."""
    monkeypatch.setenv("AIOFL_CACHE_DIR", str(tmp_path / "cache"))
    plant, other = fresh, dataclasses.replace(fresh)
    monkeypatch.setattr(lane_choice, "LONE_STEPS_PER_COMPILE", 100.0)
    price = 100.0 * numba.get_num_threads()
    assert not lane_choice.lanes_worth_it(plant, False, 0.4 * price)
    assert not lane_choice.lanes_worth_it(plant, False, 0.4 * price)
    assert lane_choice.rent(plant, False) == pytest.approx(0.8 * price)
    assert lane_choice.rent(other, False) == 0.0 and lane_choice.rent(plant, True) == 0.0
    assert lane_choice.lanes_worth_it(plant, False, 0.2 * price)  # rent + steps = price
    assert lane_choice.rent(plant, False) == 0.0
    assert lane_choice.lanes_worth_it(other, True, price)  # worth it alone
    assert not lane_choice.lanes_worth_it(other, False, 0.5 * price)


def test_a_small_batch_of_a_plant_without_lanes_runs_alone_with_the_same_numbers(
    fresh, monkeypatch
):
    """``engine="auto"``: a kind with enough members for lanes runs alone when its lane
    instance is not at hand (the test's premise: whether another test stored the
    pendulum's is beside the point here) and the work is below the price (nothing compiled
    for lanes); ``engine="lanes"`` plans the same batch in one group.  The members' numbers
    are those they have alone, bit for bit."""
    plant = fresh
    monkeypatch.setattr(lane_choice, "lanes_at_hand", lambda plant, sampled_data: False)
    ctrls, scen = _members(20)
    plans = []
    real_plan = simulation.plan
    monkeypatch.setattr(
        simulation, "plan", lambda *a: plans.append((a, real_plan(*a))) or plans[-1][1]
    )
    res = simulate_batch(plant, ctrls, scen, dt=1e-3)
    (rec, engine, _), planned = plans[0]
    assert engine == "auto" and list(planned) == [(1, False)]
    assert planned[(1, False)].shape == (20, 1)
    assert not instances.instance_built(plant, WIDTH)
    assert lane_choice.rent(plant, False) == 20 * rec.n_steps
    assert list(real_plan(rec, "lanes", plant)) == [(WIDTH, False)]
    for i in (0, 19):
        alone = simulate_batch(plant, ctrls[i], scen, dt=1e-3)
        np.testing.assert_array_equal(alone.metrics[0], res.metrics[i])


def test_declared_work_worth_the_compile_buys_the_lanes_at_the_first_batch(
    fresh, tmp_path, monkeypatch
):
    """A process that declares work reaching the price (a tuning run's budget) runs its
    first batch in lanes without paying rent; a declaration below the price changes
    nothing, and a new one replaces the last."""
    monkeypatch.setenv("AIOFL_CACHE_DIR", str(tmp_path / "cache"))
    plant = fresh
    monkeypatch.setattr(lane_choice, "LONE_STEPS_PER_COMPILE", 100.0)
    price = 100.0 * numba.get_num_threads()
    lane_choice.expect(plant, False, 0.5 * price)
    assert not lane_choice.lanes_worth_it(plant, False, 1.0)
    lane_choice.expect(plant, False, price)
    assert lane_choice.lanes_worth_it(plant, False, 1.0)
    assert lane_choice.rent(plant, False) == 0.0
    assert not lane_choice.lanes_worth_it(plant, True, 1.0)  # declared for the other timing


def test_a_tuning_run_declares_its_whole_budget(monkeypatch):
    """population × generations candidates, each (robust draws + 1) × noise realisations
    members of the tuning horizon's steps, declared at its first evaluation."""
    from aiofl.config import parse_config
    from aiofl.tuning.evaluate import evaluate_chunk
    from aiofl.tuning.search import prepare
    from test_tuning import FAST

    cfg = parse_config(
        {**FAST, "tune": {**FAST["tune"], "population": 6, "generations": 7}}, "a test config"
    )
    prep = prepare(cfg)
    assert prep.spec.expected_candidates == 6 * 7
    declared = []
    monkeypatch.setattr(lane_choice, "expect", lambda *a: declared.append(a))
    evaluate_chunk(prep.spec, prep.space.decode(prep.initial[:1]))
    n_steps = round(prep.spec.t_final / prep.spec.dt)
    assert len(declared) == 1 and declared[0][1:] == (False, 6 * 7 * n_steps)
