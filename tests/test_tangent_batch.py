"""The Jacobian of the orbit loop: the Python tangent batch and the compiled loop.

The Python reference (:meth:`aiofl.analysis.orbit_loop.OrbitLoop.rhs`) evaluates the loop
once on the n_z complex steps :math:`z + ihe_j` as the columns of a batch (the plant's
functions by :meth:`aiofl.analysis.derivatives.PlantDerivatives.evaluate_columns`, the
non-smooth elements by their value and slope at the shared real part).  It must equal the
complex step taken column by column (one scalar right-hand side call per column, the
definition) to the last bit, for every controller structure, on a plant differentiated by
the complex step and on one whose complex step falls back to finite differences; so must
the describing-function Jacobian, the nonlinearities' error rows, and a batch whose columns
are at different real points.  :meth:`~aiofl.analysis.orbit_loop.OrbitLoop.jacobian_at`,
compiled (:mod:`aiofl.analysis.compiled_loop`, forward mode), must equal the same
column-by-column complex step to rounding (:func:`_assert_close`: the sums are formed in
another order).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from aiofl.analysis.derivatives import COMPLEX_STEP
from aiofl.analysis.orbit_loop import OrbitLoop
from aiofl.config import load_config


def _column_by_column(loop: OrbitLoop, z: np.ndarray, rd=None, d=None) -> np.ndarray:
    cols = []
    for j in range(loop.n_z):
        zc = z.astype(np.complex128)
        zc[j] += 1j * COMPLEX_STEP
        cols.append(loop.rhs(zc, rd=rd, d=d)[0].imag / COMPLEX_STEP)
    return np.column_stack(cols)


def _assert_same(a: np.ndarray, b: np.ndarray) -> None:
    """Equal to the last bit.  Not a tolerance: scipy's BDF takes its Newton iterations,
    hence its steps, from this Jacobian, and an orbit it integrates over hundreds of
    periods' worth of steps moves with them (differences of 3e-15 in a few entries, from
    numpy dividing a complex array by multiplying with the reciprocal, changed
    retuned-s1-inleso's largest Floquet multiplier from 0.90 to 0.53)."""
    assert a.shape == b.shape
    assert np.array_equal(a, b), float(np.max(np.abs(a - b) / np.maximum(np.abs(b), 1e-300)))


def _python_batch(loop: OrbitLoop, z: np.ndarray, rd=None, d=None) -> np.ndarray:
    """The Python reference's Jacobian: one call on the tangent batch."""
    return loop.rhs(loop.tangent_batch(z), rd=rd, d=d)[0].imag / COMPLEX_STEP


CLOSE = 1e-12
"""The compiled Jacobian equals the complex step to this, relative to its row's largest
entry (rounding: both are exact derivatives, summed in another order)."""


def _assert_close(a: np.ndarray, b: np.ndarray) -> None:
    assert a.shape == b.shape
    scale = np.max(np.abs(b), axis=1, keepdims=True)
    err = np.abs(a - b)
    assert np.all(err <= CLOSE * scale + 1e-300), float(np.max(err / np.maximum(scale, 1e-300)))


def _loop(preset: str, **change: object) -> OrbitLoop:
    cfg = load_config(preset)
    ctrl = cfg.controller
    td = change.pop("td", None)
    if td is not None:
        ctrl = replace(ctrl, td=td)
    if change:
        ctrl = ctrl.with_values(**change)
    loop = OrbitLoop(cfg.plant, ctrl, cfg.scenario, dt=float(cfg.dt))
    if ctrl.td == "han":
        loop.han_signal(0.0, 1.0)
    return loop


def _points(loop: OrbitLoop, count: int = 3) -> list[np.ndarray]:
    """States around the loop's initial guess, spread so that fal, g(e) and the INLSEF
    run on both branches."""
    z = loop.initial_guess()
    rng = np.random.default_rng(7)
    return [
        z + 0.05 * rng.standard_normal(z.size) * np.maximum(np.abs(z), 1.0) for _ in range(count)
    ]


STRUCTURES = [
    ("paper-s1-leso", {}),  # linear ESO, fal NLSEF, Han TD (an input)
    ("retuned-s1-inleso", {}),  # INLESO g(e), INLSEF with its tanh limit, improved TD
    ("retuned-s1-ladrc", {}),  # linear ESO and SEF
    ("retuned-s1-ladrc", {"td": "linear", "td.omega": 25.0}),  # linear prefilter
    ("assisted-s1-ladrc", {}),  # model-assisted law, eso.model = "nominal"
    ("iofl-s1", {}),  # classical IOFL law on the normal form
    ("paper-s2-inleso", {"law.u_max": 1e-3}),  # saturation active (slope 0)
]


@pytest.mark.parametrize(("preset", "change"), STRUCTURES)
def test_batch_jacobian_equals_the_column_by_column_complex_step(
    preset: str, change: dict[str, object]
) -> None:
    loop = _loop(preset, **change)
    for k, z in enumerate(_points(loop)):
        rd, d = loop.inputs_at(0.21 * k), 0.1 * k
        batch = _python_batch(loop, z, rd, d)
        by_column = _column_by_column(loop, z, rd, d)
        _assert_same(batch, by_column)
        _assert_close(loop.jacobian_at(z, rd, d), by_column)
        assert np.any(batch != 0.0)
    if "law.u_max" in change:  # every column saturated: u does not move
        assert np.all(np.abs(loop.rhs(z, rd, d)[2]) <= 1e-3)
        assert np.all(np.imag(loop.rhs(loop.tangent_batch(z), rd, d)[2]) == 0.0)


@pytest.mark.parametrize("preset", ["paper-s1-leso", "retuned-s1-inleso"])
def test_describing_jacobian_and_error_rows_equal_column_by_column(preset: str) -> None:
    loop = _loop(preset)
    z = _points(loop, 1)[0]
    loop.describing = tuple(0.5 + 0.1 * i for i in range(len(loop.nonlinearities())))
    try:
        by_column = _column_by_column(loop, z)
        _assert_same(_python_batch(loop, z), by_column)
        _assert_close(loop.jacobian_at(z), by_column)
    finally:
        loop.describing = None
    rows = []
    for j in range(loop.n_z):  # the recorded inputs' complex steps, one column at a time
        zc = z.astype(np.complex128)
        zc[j] += 1j * COMPLEX_STEP
        loop._record = []
        loop.rhs(zc)
        rows.append([complex(v).imag / COMPLEX_STEP for v in loop._record])
    loop._record = []
    loop.rhs(loop.tangent_batch(z))  # the Python reference's batch
    batch_rows = [np.asarray(v).imag / COMPLEX_STEP for v in loop._record]
    loop._record = None
    _assert_same(np.array(batch_rows).reshape(-1, loop.n_z), np.array(rows).T)
    _assert_close(loop.error_rows(z), np.array(rows).T)


def test_a_batch_at_different_real_points_is_each_columns_value() -> None:
    """Columns that do not share a real point (no tangent batch) are evaluated one by one:
    the plant's functions and the non-smooth elements give each column's own value."""
    loop = _loop("retuned-s1-inleso")
    zs = np.column_stack(_points(loop, 4)).astype(np.complex128)
    zs.imag[2] = 1e-30
    dz, y, u = loop.rhs(zs, loop.inputs_at(0.1), 0.05)
    for k in range(zs.shape[1]):
        dzk, yk, uk = loop.rhs(zs[:, k], loop.inputs_at(0.1), 0.05)
        assert np.array_equal(dz[:, k], dzk)
        assert (y[k], u[k]) == (yk, uk)


def test_batch_jacobian_with_the_finite_difference_fallback() -> None:
    from test_linearize import tank_f_erf, tank_plant

    cfg = load_config("tank-ladrc")
    plant = tank_plant("erf-tank", tank_f_erf)  # math.erf: no complex version
    loops = [OrbitLoop(plant, cfg.controller, cfg.scenario) for _ in range(2)]
    z = loops[0].operating_point() + 0.01
    batch = loops[0].jacobian_at(z)  # the first call meets the ComplexWarning
    assert loops[0].derivatives.method["f"] == "finite difference"
    assert any("ComplexWarning" in n for n in loops[0].derivatives.notes)
    assert loops[0].derivatives.method["g"] == loops[0].derivatives.method["h"] == "complex step"
    assert loops[0].compiled.jets is None  # f not exact: the plant's Jacobians from Python
    _assert_same(_python_batch(loops[0], z), _column_by_column(loops[1], z))
    _assert_close(batch, _column_by_column(loops[1], z))
    assert loops[1].derivatives.notes == loops[0].derivatives.notes
    # d/dH of −a√H + 1e-3·erf(H − 1): the finite difference to ~1e-8
    slope = -0.2 / (2 * math.sqrt(z[0])) + 1e-3 * 2 / math.sqrt(math.pi) * math.exp(
        -((z[0] - 1) ** 2)
    )
    assert batch[0, 0] == pytest.approx(slope, rel=1e-7)


def test_the_finite_difference_cache_is_bounded_and_changes_no_value() -> None:
    """The finite-difference Jacobians a plant's derivatives keep: at most
    ``FD_CACHE_SIZE`` (an orbit visits ~10⁵ states; the cache grew with each), the most
    recently used kept, and an evicted one computed again is the same to the last bit."""
    from aiofl.analysis.derivatives import FD_CACHE_SIZE, PlantDerivatives
    from test_linearize import tank_f_erf, tank_plant

    plant = tank_plant("erf-tank", tank_f_erf)
    der = PlantDerivatives(plant)
    p = np.array(list(plant.params.values()))
    first = der.fd_jacobian("f", np.array([0.5]), p).copy()
    for k in range(FD_CACHE_SIZE + 40):
        der.fd_jacobian("f", np.array([0.6 + 1e-3 * k]), p)
        der.fd_jacobian("f", np.array([0.6]), p)  # used again and again: stays
    assert len(der._fd_cache) == FD_CACHE_SIZE
    assert ("f", np.array([0.6]).tobytes(), p.tobytes()) in der._fd_cache
    assert ("f", np.array([0.5]).tobytes(), p.tobytes()) not in der._fd_cache  # evicted
    assert np.array_equal(der.fd_jacobian("f", np.array([0.5]), p), first)


def test_reads_first_argument_only_where_the_code_never_touches_x() -> None:
    """A plant function that never reads x is evaluated once per batch (constant in x);
    anything that might read it is not."""
    from aiofl.analysis.derivatives import reads_first_argument

    def gain(x, p):
        return (0.0, p[0])

    def uses(x, p):
        return (x[0] * p[0],)

    def captures(x, p):
        return (lambda: x[0])()

    def dynamic(x, p):
        return (locals()["x"][0],)

    def rebinds(x, p):
        x = p
        return (x[0],)

    assert not reads_first_argument(gain)
    assert all(reads_first_argument(fn) for fn in (uses, captures, dynamic, rebinds, len, None))
    cfg = load_config("retuned-s1-inleso")
    loop = OrbitLoop(cfg.plant, cfg.controller, cfg.scenario)
    assert loop.derivatives.reads_state["f"] and loop.derivatives.reads_state["h"]
    assert not loop.derivatives.reads_state["g"]  # slfjm's input gain b = k_m k_g / (R_m J_h)


def test_the_orbit_jacobian_checks_the_plants_complex_step_first() -> None:
    """A plant written with numpy.abs (the modulus of a complex step: its derivative is
    lost) is caught at the orbit loop's first Jacobian: its plant Jacobian comes from finite
    differences (noted), and the loop's Jacobian equals that of the same plant written with
    abs (exact) to ~1e-8; unchecked, ∂(−a√|H|)/∂H came out 0."""
    from test_linearize import tank_f_abs, tank_f_numpy_abs, tank_plant

    cfg = load_config("tank-ladrc")
    jac = {}
    for name, f in (("builtin", tank_f_abs), ("numpy", tank_f_numpy_abs)):
        loop = OrbitLoop(tank_plant(name, f), cfg.controller, cfg.scenario, dt=float(cfg.dt))
        z = loop.initial_guess()
        z[0] = 1.0
        jac[name] = loop.jacobian_at(z)
        notes = loop.derivatives.notes
        assert any("finite differences" in n for n in notes) == (name == "numpy")
    assert jac["builtin"][0, 0] == pytest.approx(-0.1, rel=1e-14)  # −a/(2√H) at H = 1
    assert np.allclose(jac["numpy"], jac["builtin"], rtol=1e-8, atol=1e-10)
