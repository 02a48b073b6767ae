"""The closed loop compiled with its exact Jacobian equals the Python reference.

:class:`aiofl.analysis.compiled_loop.CompiledLoop` evaluates the loop the analyses study
(linearisation, margins, the sampled loop, orbits) in compiled code, with the plant's
Jacobians from its compiled jets (:mod:`aiofl.analysis.plant_jets`).  Its linear model
must equal the complex step of the Python reference
(:meth:`aiofl.analysis.closed_loop.ClosedLoop.rhs`, column by column, the definition) to
rounding on every controller structure and plant kind, the margins computed from it must
equal the reference's, a rig plant (whose functions wrap the bare plant's compiled ones)
must be differentiated exactly rather than fail, and a plant whose functions cannot be
compiled for complex numbers must still work through Python.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np
import pytest

from aiofl.analysis.closed_loop import ClosedLoop
from aiofl.analysis.derivatives import COMPLEX_STEP, complex_safe
from aiofl.config import load_config

CLOSE = 1e-12
"""Compiled and reference Jacobians agree to this, relative to each row's largest entry
(both are exact derivatives; the sums are formed in another order)."""


def reference_linear_model(loop: ClosedLoop, z: np.ndarray, broken: bool = False) -> Any:
    """(A, B, C, D) by the complex step of the Python reference, one column at a time (the
    implementation the compiled loop replaced)."""
    v = loop.operating_inputs()
    u_star = loop.rhs(z)[2] if broken else None
    n_in = 1 if broken else v.size
    cols = []
    for j in range(loop.n_z + n_in):
        zc = z.astype(np.complex128)
        vc = v.astype(np.complex128)
        up = None if u_star is None else complex(u_star)
        if j < loop.n_z:
            zc[j] += 1j * COMPLEX_STEP
        elif broken:
            up += 1j * COMPLEX_STEP
        else:
            vc[j - loop.n_z] += 1j * COMPLEX_STEP
        rd, d, noise = loop._inputs_split(vc)
        dz, y, u = loop.rhs(zc, rd=rd, d=d, noise=noise, u_plant=up)
        cols.append(np.concatenate([dz.imag, [np.imag(y), np.imag(u)]]) / COMPLEX_STEP)
    jac = np.column_stack(cols)
    nz = loop.n_z
    a, b, c, d = jac[:nz, :nz], jac[:nz, nz:], jac[nz:, :nz], jac[nz:, nz:]
    return (a, b, c[1:], d[1:]) if broken else (a, b, c, d)


def _assert_close(got: np.ndarray, ref: np.ndarray) -> None:
    assert got.shape == ref.shape
    if not ref.size:
        return
    scale = np.max(np.abs(np.hstack([ref, got])), axis=1, keepdims=True)
    err = np.abs(got - ref)
    assert np.all(err <= CLOSE * scale + 1e-300), float(np.max(err / np.maximum(scale, 1e-300)))


STRUCTURES = [
    ("frontier-s1-ladrc", {}),  # linear ESO and SEF, exact profile, slfjm
    ("paper-s1-leso", {}),  # fal NLSEF (secant gains), Han TD held
    ("retuned-s1-inleso", {}),  # INLESO g(e), INLSEF, improved TD
    ("retuned-s1-ladrc", {"td": "linear", "td.omega": 25.0}),  # linear prefilter
    ("assisted-s1-ladrc", {}),  # model-assisted observer: (α, β)(ξ̂)
    ("iofl-s1", {}),  # classical IOFL law: the normal form
    ("rig-s1-ladrc", {}),  # a rig plant (wraps slfjm's compiled functions), model-assisted
    ("tank-ladrc", {}),  # tank: sqrt
    ("flexjoint-hub-ladrc", {}),
    ("dcmotor-arm-ladrc", {}),
]


def _config(preset: str, change: dict[str, object]) -> Any:
    cfg = load_config(preset)
    change = dict(change)
    ctrl = cfg.controller
    td = change.pop("td", None)
    if td is not None:
        ctrl = replace(ctrl, td=td)
    if change:
        ctrl = ctrl.with_values(**change)
    return cfg.plant, ctrl, cfg.scenario


@pytest.mark.parametrize(("preset", "change"), STRUCTURES)
def test_compiled_linear_model_equals_the_complex_step_reference(
    preset: str, change: dict[str, object]
) -> None:
    """A, B, C, D, closed and broken at the plant input, at the operating point and at a
    state beside it; the compiled plant jets are used (not the Python fallback)."""
    plant, ctrl, scenario = _config(preset, change)
    loop = ClosedLoop(plant, ctrl, scenario)
    z_op = loop.operating_point()
    rng = np.random.default_rng(3)
    beside = z_op + 1e-3 * rng.standard_normal(z_op.size) * np.maximum(np.abs(z_op), 1.0)
    for z in (z_op, beside):
        for broken in (False, True):
            got = loop.linear_model(z, broken=broken)
            ref = reference_linear_model(loop, z, broken)
            for g, r in zip(got, ref, strict=True):
                _assert_close(g, r)
        assert np.array_equal(loop.compiled.rhs(z), loop.rhs(z)[0]) or np.allclose(
            loop.compiled.rhs(z), loop.rhs(z)[0], rtol=1e-13, atol=1e-300
        )
    assert loop.compiled.jets is not None
    assert not loop.derivatives.notes


@pytest.mark.parametrize("preset", ["frontier-s1-ladrc", "assisted-s1-ladrc", "rig-s1-ladrc"])
def test_margins_from_the_compiled_loop_equal_the_references(preset: str) -> None:
    """Gain, phase and delay margins and Ms of the loop broken at the plant input: from the
    compiled linear model and from the reference's, equal to 1e-9 relative; the frequency
    of Ms, the top of a flat peak (its location moves as the square root of a change in
    the curve), to 1e-5."""
    from aiofl.analysis.frequency import loop_margins, loop_transfer

    plant, ctrl, scenario = _config(preset, {})
    loop = ClosedLoop(plant, ctrl, scenario)
    z = loop.operating_point()
    a = loop.linear_model(z)[0]
    eig = np.linalg.eigvals(a)
    got = loop_margins(loop_transfer(*loop.linear_model(z, broken=True)), eig).to_dict()
    ref = loop_margins(loop_transfer(*reference_linear_model(loop, z, True)), eig).to_dict()
    assert got.keys() == ref.keys()
    for key, value in ref.items():
        if isinstance(value, float) and math.isfinite(value):
            rel = 1e-5 if key == "ms_frequency_rad_s" else 1e-9
            assert got[key] == pytest.approx(value, rel=rel), key
        else:
            assert got[key] == value, key


def test_the_rig_plants_loop_has_exact_jacobians_and_margins() -> None:
    """rig-s1-ladrc (plant slfjm+rig, model-assisted observer): its functions call slfjm's
    numba-compiled ones.  The complex step used to reach them and stop with numba's
    TypingError (sin(complex128)); now every function is differentiated exactly (no
    finite-difference note), the plant's Jacobian equals scipy's finite difference, and
    the verdict carries the margins (its equilibrium is the reference's)."""
    from scipy.differentiate import jacobian

    from aiofl.analysis.linearize import closed_loop_verdict

    cfg = load_config("rig-s1-ladrc")
    loop = ClosedLoop(cfg.plant, cfg.controller, cfg.scenario)
    z = loop.operating_point()
    loop.linear_model(z)
    assert all(m == "complex step" for m in loop.derivatives.method.values())
    assert loop.compiled.jets is not None
    x = z[: loop.n] + 0.01
    value, jac = loop.derivatives.jet("f", x, loop.p_true)
    fd = jacobian(
        lambda xs: np.apply_along_axis(lambda c: cfg.plant.f(c, loop.p_true), 0, xs), x
    ).df
    assert np.allclose(jac, fd, rtol=1e-7, atol=1e-6)
    assert np.array_equal(value, np.asarray(cfg.plant.f(x, loop.p_true)))
    verdict = closed_loop_verdict(cfg)
    ref_a = reference_linear_model(loop, z)[0]
    assert verdict["max_real"] == pytest.approx(float(np.max(np.linalg.eigvals(ref_a).real)))
    assert verdict["gain_margin_db"] is not None and verdict["phase_margin_deg"] is not None
    assert verdict["ms"] is not None


def test_complex_safe_follows_compiled_callees_and_numpy_arrays() -> None:
    """A function that calls a numba-compiled helper (through its closure) and fills an
    ``np.empty`` array is re-bound through both: its complex step is the derivative."""
    from numba import njit

    @njit
    def inner(x: np.ndarray) -> float:
        return math.sin(x[0]) * x[1]

    def make() -> Any:
        helper = inner

        def fn(x: np.ndarray, p: np.ndarray) -> np.ndarray:
            out = np.empty(2)
            out[0] = helper(x)
            out[1] = p[0] * x[1] ** 2
            return out

        return fn

    cfn = complex_safe(make())
    assert cfn is not None
    x = np.array([0.3, 2.0], dtype=np.complex128)
    x[0] += 1j * COMPLEX_STEP
    d0 = np.asarray(cfn(x, np.array([1.5]))).imag / COMPLEX_STEP
    assert d0[0] == pytest.approx(math.cos(0.3) * 2.0, rel=1e-15)
    assert d0[1] == 0.0


def test_a_plant_not_compilable_for_complex_numbers_runs_through_python() -> None:
    """math.erf has no complex version: the plant has no compiled jets, its f is
    differentiated by finite differences (noted) and the compiled loop's A equals the
    reference's (both from that finite difference)."""
    from aiofl.analysis.plant_jets import plant_jets
    from test_linearize import tank_f_erf, tank_plant

    cfg = load_config("tank-ladrc")
    plant = tank_plant("erf-tank", tank_f_erf)
    assert plant_jets(plant) is None
    loop = ClosedLoop(plant, cfg.controller, cfg.scenario)
    z = loop.operating_point()
    a = loop.linear_model(z)[0]
    assert any("finite differences" in n for n in loop.derivatives.notes)
    assert loop.compiled.jets is None
    _assert_close(a, reference_linear_model(loop, z)[0])


def _python_field(loop: Any) -> Any:
    """The orbit loop's (F, J) from the Python reference: :meth:`OrbitLoop.rhs` and its
    tangent batch (what the orbit analysis evaluated before the compiled loop)."""

    def field(*, hold: bool = False, d: float | None = None) -> Any:
        def inputs(t: float) -> tuple[Any, float]:
            rd = None if hold else loop.inputs_at(t)
            return rd, loop.disturbance_at(t) if d is None else d

        def f(t: float, z: np.ndarray) -> np.ndarray:
            rd, dd = inputs(t)
            return loop.rhs(z, rd=rd, d=dd)[0]

        def jac(t: float, z: np.ndarray) -> np.ndarray:
            rd, dd = inputs(t)
            return loop.rhs(loop.tangent_batch(z), rd=rd, d=dd)[0].imag / COMPLEX_STEP

        return f, jac

    return field


@pytest.mark.parametrize("preset", ["flexjoint-hub-ladrc", "frontier-s3-ladrc"])
def test_floquet_multipliers_from_the_compiled_loop_equal_the_references(preset: str) -> None:
    """The tracking orbit's largest Floquet multiplier (an orbit that closes to 1e-5),
    integrated with the compiled loop and with the Python reference: equal to 1e-4
    relative (the integrations run at rtol 1e-6 on step sequences that differ with the
    last bits of F and J)."""
    from aiofl.analysis.orbit import tracking_floquet
    from aiofl.analysis.orbit_loop import OrbitLoop

    cfg = load_config(preset)
    results = {}
    for how in ("compiled", "python"):
        loop = OrbitLoop(cfg.plant, cfg.controller, cfg.scenario, dt=float(cfg.dt))
        if how == "python":
            loop.field = _python_field(loop)  # type: ignore[method-assign]
        results[how] = tracking_floquet(loop)
    got, ref = results["compiled"], results["python"]
    assert ref["closing"] < 1e-4 and got["closing"] < 1e-4
    assert got["largest"] == pytest.approx(ref["largest"], rel=1e-4)
    assert 0.0 < ref["largest"] < 1.0


def test_the_rig_friction_far_from_zero_velocity_is_finite_and_exact() -> None:
    """The rig's friction F_c·tanh(v/ε) at a velocity hundreds of ε away from 0: numba's
    complex numpy.tanh gives NaN there (its exponentials overflow); the compiled jets use
    cmath's, so the compiled Jacobian is finite and equals the Python reference's (the
    tracking orbits of rig-s*-ladrc failed on it with "array must not contain infs or
    NaNs")."""
    from aiofl.analysis.orbit_loop import OrbitLoop

    cfg = load_config("rig-s3-ladrc")
    loop = OrbitLoop(cfg.plant, cfg.controller, cfg.scenario, dt=float(cfg.dt))
    z = loop.operating_point()
    iv = cfg.plant.state_names.index(cfg.rig.friction_state)
    eps = loop.p_true[list(cfg.plant.params).index("rig_eps")]
    z[iv] = 800.0 * eps  # tanh's argument 800
    got = loop.jacobian_at(z)
    assert loop.compiled.jets is not None
    ref = loop.rhs(loop.tangent_batch(z))[0].imag / COMPLEX_STEP
    assert np.all(np.isfinite(got))
    _assert_close(got, ref)
