"""Hostile plant files and user plants that fail (issue 8, slice B).

* Expression strings are bounded before sympy builds anything: power towers, large integer
  exponents, deep nesting, thousands of signs, oversized plants, non-finite and complex
  constants are each refused with a SymbolicPlantError naming the field and the limit.
* A property test (hypothesis, derandomized) feeds random bounded expression strings and
  mutations of the shipped specs: the outcome is a SymbolicPlantError or a valid plant
  whose generated code is finite, never another exception or a hang.
* User plant functions: complex results, code numba cannot compile, a function that raises
  at run time (PlantError naming the function and the state) and one that divides by zero
  (the member diverges, with its time).

Hang guards (``_no_hang``) use a generous SIGALRM limit: they fail a test that would
otherwise never end, they do not measure speed (``benchmarks/fuzz_plant_files.py`` does).
"""

from __future__ import annotations

import contextlib
import copy
import math
import re
import signal
import string
from collections.abc import Iterator
from datetime import timedelta
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import sympy as sp
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from aiofl.plants.base import Plant, PlantError
from aiofl.plants.expressions import (
    MAX_EXPANDED_TERMS,
    MAX_EXPONENT,
    MAX_EXPRESSION_CHARS,
    MAX_EXPRESSION_DEPTH,
    MAX_EXPRESSION_NODES,
    MAX_PARAMS,
    MAX_STATES,
    SymbolicPlantError,
    expanded_terms,
    parse_expression,
)
from aiofl.plants.library import SPECS
from aiofl.plants.symbolic import SymbolicPlant

PENDULUM: dict[str, Any] = {
    "name": "pend",
    "states": ["x1", "x2"],
    "f": ["x2", "-g*sin(x1) - c*x2"],
    "g": ["0", "b"],
    "h": "x1",
    "params": {"g": 9.81, "c": 0.1, "b": 4.0},
}


@contextlib.contextmanager
def _no_hang(seconds: float) -> Iterator[None]:
    """Fail (TimeoutError) instead of hanging when the body runs past ``seconds``."""

    def alarm(signum: int, frame: Any) -> None:
        raise TimeoutError(f"no answer in {seconds} s")

    old = signal.signal(signal.SIGALRM, alarm)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)


def _plant(**changes: Any) -> SymbolicPlant:
    return SymbolicPlant.from_dict({**copy.deepcopy(PENDULUM), **changes})


def _f2(expr: str) -> dict[str, Any]:
    return {"f": ["x2", expr]}


# --------------------------------------------------------------- hostile expressions

HOSTILE = [
    # (changes to the pendulum spec, the field named, a fragment of the message)
    (_f2("10**10**10"), "f[2]", f"|n| <= {MAX_EXPONENT}"),
    (_f2("9**9**9"), "f[2]", f"|n| <= {MAX_EXPONENT}"),
    (_f2("(-2)**(2**70)"), "f[2]", f"|n| <= {MAX_EXPONENT}"),
    (_f2("(x1+1)**200"), "f[2]", "exponent 200"),
    (_f2("(x1+1)**-200"), "f[2]", "exponent -200"),
    (_f2("x1**1e300"), "f[2]", f"|n| <= {MAX_EXPONENT}"),
    (_f2("((x1+1)**16)**16"), "f[2]", f"at most {MAX_EXPANDED_TERMS}"),
    (_f2("(x1+x2+b+c+1)**40"), "f[2]", f"at most {MAX_EXPANDED_TERMS}"),
    (_f2("sin(" * 100 + "x1" + ")" * 100), "f[2]", f"{MAX_EXPRESSION_DEPTH} levels"),
    (_f2("x1*(" * 60 + "x2" + ")" * 60), "f[2]", f"{MAX_EXPRESSION_DEPTH} levels"),
    (_f2("(" * 1000 + "x1" + ")" * 1000), "f[2]", "too many nested parentheses"),
    (_f2("-" * 2000 + "x1"), "f[2]", "2000 unary signs"),
    (_f2("+-" * 1000 + "x1"), "f[2]", "2000 unary signs"),
    (_f2("-" * 20000 + "x1"), "f[2]", f"at most {MAX_EXPRESSION_CHARS}"),
    (_f2("+".join(["x1*x2"] * 600)), "f[2]", f"at most {MAX_EXPRESSION_NODES}"),
    (_f2("1" + "0" * 400 + "*x1"), "f[2]", "outside the float64 range"),
    (_f2("1/0"), "f[2]", "division by zero"),
    (_f2("x1/0"), "f[2]", "division by zero"),
    (_f2("0/0"), "f[2]", "division by zero"),
    (_f2("0**-1"), "f[2]", "division by zero"),
    (_f2("1/(x1-x1)"), "f[2]", "not finite"),
    (_f2("atan2(0, 0)"), "f[2]", "not finite"),
    (_f2("tan(pi/2)*x1"), "f[2]", "not finite"),
    (_f2("log(0)"), "f[2]", "log(0)"),
    (_f2("x1 + 1e400"), "f[2]", "not a finite real number"),
    (_f2("1e308*10"), "f[2]", "overflows"),
    (_f2("exp(1000)*x1"), "f[2]", "exp(1000) overflows"),
    (_f2("exp(exp(exp(exp(10))))"), "f[2]", "overflows"),
    (_f2("(1e300*x1)*(1e300*x2)"), "f[2]", "outside the float64 range"),
    (_f2("sqrt(-1)"), "f[2]", "sqrt(-1)"),
    (_f2("(-8)**(1/3)"), "f[2]", "complex"),
    (_f2("sqrt(x1 - x1 - 1)"), "f[2]", "complex"),
    ({"g": ["0", "1/0"]}, "g[2]", "division by zero"),
    ({"h": "x1 + 1/0"}, "h", "division by zero"),
    ({"bd": ["0", "log(0)"]}, "bd[2]", "log(0)"),
    ({"eta": ["x1**200"]}, "eta[1]", "exponent 200"),
    ({"params": {"g": 1e400, "c": 0.1, "b": 4.0}}, "params.g", "finite"),
    ({"params": {"g": 10**400, "c": 0.1, "b": 4.0}}, "params.g", "finite"),
    ({"equilibrium": [math.inf, 0.0]}, "equilibrium[1]", "finite"),
    ({"equilibrium": ["a", 0.0]}, "equilibrium[1]", "finite"),
]


@pytest.mark.parametrize(("changes", "field", "fragment"), HOSTILE)
def test_hostile_expression_is_refused_naming_the_field_and_the_limit(
    changes: dict[str, Any], field: str, fragment: str
) -> None:
    with _no_hang(5.0), pytest.raises(SymbolicPlantError) as err:
        _plant(**changes)
    msg = str(err.value)
    assert field in msg and fragment in msg, msg
    assert len(msg) < 600  # one line, the expression cut short


def test_a_plant_of_1000_states_or_parameters_is_refused_before_parsing() -> None:
    names = [f"s{i}" for i in range(1000)]
    spec = {
        "states": names,
        "params": {"k": 1.0},
        "f": ["10**10**10"] * 1000,  # never parsed: the count is checked first
        "g": ["1"] * 1000,
        "h": "s0",
    }
    with _no_hang(5.0), pytest.raises(SymbolicPlantError, match=f"at most {MAX_STATES}"):
        SymbolicPlant.from_dict(spec)
    params = {f"q{i}": 1.0 for i in range(MAX_PARAMS + 1)}
    with pytest.raises(SymbolicPlantError, match=f"at most {MAX_PARAMS}"):
        _plant(params=params)


def test_limits_are_inclusive_at_the_boundary() -> None:
    x = sp.Symbol("x", real=True)
    syms = {"x": x}
    assert parse_expression(f"x**{MAX_EXPONENT}", syms) == x**MAX_EXPONENT
    assert parse_expression(f"x**-{MAX_EXPONENT}", syms) == x**-MAX_EXPONENT
    with pytest.raises(SymbolicPlantError, match="exponent 65"):
        parse_expression(f"x**{MAX_EXPONENT + 1}", syms)
    nested = "sin(" * (MAX_EXPRESSION_DEPTH - 1) + "x" + ")" * (MAX_EXPRESSION_DEPTH - 1)
    parse_expression(nested, syms)
    deeper = "sin(" * (MAX_EXPRESSION_DEPTH + 1) + "x" + ")" * (MAX_EXPRESSION_DEPTH + 1)
    with pytest.raises(SymbolicPlantError, match="nesting deeper"):
        parse_expression(deeper, syms)
    # a written-out sum is one level deep however long it is (the walk is a loop)
    parse_expression("+".join(["x"] * 400), syms)


def test_parsing_agrees_with_sympy_on_legal_expressions() -> None:
    x1, x2, k = sp.symbols("x1 x2 k", real=True)
    syms = {"x1": x1, "x2": x2, "k": k}
    cases = {
        "-k*x1**2 + 3/4*x2": -k * x1**2 + sp.Rational(3, 4) * x2,
        "x1/x2/k": x1 / x2 / k,
        "x1 - x2 - k": x1 - x2 - k,
        "2**64*x1": 2**64 * x1,
        "x1**(1/3) + abs(x2)": x1 ** sp.Rational(1, 3) + sp.Abs(x2),
        "min(x1, x2) - max(x1, k)": sp.Min(x1, x2) - sp.Max(x1, k),
        "atan2(x2, x1) + sign(x1)*pi": sp.atan2(x2, x1) + sp.sign(x1) * sp.pi,
    }
    for text, want in cases.items():
        assert parse_expression(text, syms) == want, text


def test_expanded_terms_is_the_multinomial_count() -> None:
    x, y, z = sp.symbols("x y z")
    for e in [(x + y + 1) ** 5, (x + 1) ** 7 * (y + z), (x + y) ** 3 + (y + z + 1) ** 2]:
        # the estimate is exact when no monomials coincide ...
        assert expanded_terms(e) >= len(sp.Add.make_args(sp.expand(e)))
    assert expanded_terms((x + y + 1) ** 5) == math.comb(7, 2)
    # ... and an upper bound (a cap, not a computation) for an expansion bomb
    assert expanded_terms((x + y + z + 1) ** 10**6, cap=10**9) == 10**9


def test_generated_code_never_holds_a_bare_inf_or_nan() -> None:
    """A finite plant whose Lie derivative overflows float64 is refused by name."""
    spec = _f2("1e200*x2")
    spec["h"] = "1e200*x1"
    plant = _plant(**spec)  # every constant is finite
    with pytest.raises(SymbolicPlantError, match=r"generated normal_form.*float64"):
        plant.function_sources()
    for name in SPECS:  # and the shipped plants' code is clean
        src = "".join(SymbolicPlant.from_dict(SPECS[name]).function_sources().values())
        assert not re.search(r"\b(inf|nan|zoo)\b", src)


def test_a_constant_beta_that_is_not_finite_at_the_nominal_parameters_is_refused() -> None:
    with pytest.raises(SymbolicPlantError, match=r"β = .* zoo at the nominal parameters"):
        _plant(g=["0", "1/b"], params={"g": 9.81, "c": 0.1, "b": 0.0}).analyze()


def test_lie_derivatives_that_grow_without_bound_are_refused_naming_the_derivative() -> None:
    n = 6
    states = [f"x{i}" for i in range(1, n + 1)]
    spec = {
        "states": states,
        "params": {"k": 1.0},
        "f": [f"({states[i]} + {states[i + 1]})**4 + {states[i + 1]}" for i in range(n - 1)]
        + ["0"],
        "g": ["0"] * (n - 1) + ["1"],
        "h": "x1",
    }
    with _no_hang(120.0), pytest.raises(SymbolicPlantError, match=r"L_f\^\d h has \d+ oper"):
        SymbolicPlant.from_dict(spec).analyze()


def test_a_large_linear_chain_is_analysed_without_simplification() -> None:
    """Relative degree 12 of a chain whose Lie derivatives stay linear: ρ = n, β = 1."""
    n = 12
    states = [f"x{i}" for i in range(1, n + 1)]
    spec = {
        "states": states,
        "params": {"k": 0.5},
        "f": [f"{states[i + 1]} - k*{states[i]}" for i in range(n - 1)] + ["-k*x1"],
        "g": ["0"] * (n - 1) + ["1"],
        "h": "x1",
    }
    a = SymbolicPlant.from_dict(spec).analyze()
    assert a.rho == n and a.beta_constant and a.beta_nominal == 1.0


# ------------------------------------------------------------------- property tests

_NAMES = ["x1", "x2", "g", "c", "b", "pi"]
_NUMBERS = ["0", "1", "2", "0.5", "64", "65", "1e308", "1e-308", "1e400", "10**10", "-1"]
_FUNCS = ["sin", "cos", "tan", "exp", "log", "sqrt", "abs", "sign", "asin", "acos", "tanh"]


def _expressions() -> st.SearchStrategy[str]:
    leaves = st.sampled_from(_NAMES + _NUMBERS)

    def extend(inner: st.SearchStrategy[str]) -> st.SearchStrategy[str]:
        binop = st.tuples(inner, st.sampled_from(["+", "-", "*", "/", "**"]), inner).map(
            lambda t: f"({t[0]}){t[1]}({t[2]})"
        )
        call = st.tuples(st.sampled_from(_FUNCS), inner).map(lambda t: f"{t[0]}({t[1]})")
        two = st.tuples(st.sampled_from(["atan2", "min", "max"]), inner, inner).map(
            lambda t: f"{t[0]}({t[1]}, {t[2]})"
        )
        unary = inner.map(lambda s: f"-({s})")
        return st.one_of(binop, call, two, unary)

    grammar = st.recursive(leaves, extend, max_leaves=12)
    noise = st.text(alphabet=string.ascii_letters + string.digits + "+-*/().,^ _", max_size=30)
    return st.one_of(grammar, grammar, noise)


def _outcome(spec: dict[str, Any]) -> str:
    """'refused' (SymbolicPlantError) or 'valid' (analysed, finite generated code, plant
    constructed); any other exception propagates and fails the test."""
    try:
        plant = SymbolicPlant.from_dict(spec)
        plant.analyze()
        sources = plant.function_sources()
    except SymbolicPlantError:
        return "refused"
    for src in sources.values():
        assert not re.search(r"\b(inf|nan|zoo|oo)\b|\dj\b", src), src
    plant.to_plant()  # executes the generated code into functions
    return "valid"


@settings(
    max_examples=300,
    derandomize=True,
    deadline=timedelta(seconds=60),
    suppress_health_check=[HealthCheck.too_slow],
)
@given(expr=_expressions(), field=st.sampled_from(["f2", "g2", "h"]))
def test_random_expression_strings_are_refused_or_give_a_valid_plant(expr: str, field: str) -> None:
    spec = copy.deepcopy(PENDULUM)
    if field == "f2":
        spec["f"][1] = expr
    elif field == "g2":
        spec["g"][1] = expr
    else:
        spec["h"] = expr
    with _no_hang(120.0):
        _outcome(spec)


_MUTATIONS = ["replace", "power", "insert", "delete", "param", "drop", "wrap"]


@st.composite
def _mutated_specs(draw: st.DrawFn) -> dict[str, Any]:
    name = draw(st.sampled_from(sorted(SPECS)))
    spec = copy.deepcopy(SPECS[name])
    key = draw(st.sampled_from([k for k in ("f", "g", "bd", "h") if k in spec]))
    how = draw(st.sampled_from(_MUTATIONS))
    if how == "param":
        pname = draw(st.sampled_from(sorted(spec["params"])))
        spec["params"][pname] = draw(
            st.sampled_from([0.0, -1.0, 1e308, -1e-308, 1e-320, math.inf, math.nan, "1", True])
        )
        return spec
    if key == "h":
        old = spec["h"]
    else:
        i = draw(st.integers(0, len(spec[key]) - 1))
        old = spec[key][i]
    if how == "replace":
        new = draw(_expressions())
    elif how == "power":
        new = f"({old})**{draw(st.sampled_from([2, 3, 7, 64, 65, 300, -64, 0.5, 1e9]))}"
    elif how == "wrap":
        new = f"{draw(st.sampled_from(_FUNCS))}({old})"
    elif how == "insert":
        pos = draw(st.integers(0, len(old)))
        new = (
            old[:pos]
            + draw(st.sampled_from(["*", "/0", "**", "(", "-", "1e400", "x9"]))
            + old[pos:]
        )
    elif how == "delete":
        pos = draw(st.integers(0, max(len(old) - 1, 0)))
        new = old[:pos] + old[pos + 1 :]
    else:  # drop an entry (or blank h)
        if key == "h":
            spec["h"] = ""
        else:
            del spec[key][i]
        return spec
    if key == "h":
        spec["h"] = new
    else:
        spec[key][i] = new
    return spec


@settings(
    max_examples=40,
    derandomize=True,
    deadline=timedelta(seconds=60),
    suppress_health_check=[HealthCheck.too_slow],
)
@given(spec=_mutated_specs())
def test_mutated_shipped_specs_are_refused_or_give_a_valid_plant(spec: dict[str, Any]) -> None:
    with _no_hang(120.0):
        _outcome(spec)


def test_a_plant_file_with_a_hostile_expression_exits_2_naming_the_field(tmp_path: Path) -> None:
    from typer.testing import CliRunner

    from aiofl.cli.app import app

    path = tmp_path / "tower.toml"
    path.write_text(
        'states = ["x1", "x2"]\nf = ["x2", "10**10**10"]\ng = ["0", "1"]\nh = "x1"\n[params]\n'
    )
    with _no_hang(30.0):
        res = CliRunner().invoke(app, ["analyze", str(path), "--json"])
    assert res.exit_code == 2
    assert "f[2]" in res.stderr and f"|n| <= {MAX_EXPONENT}" in res.stderr
    assert "Traceback" not in res.stderr


# ------------------------------------------------------------ user plants that fail


def _g(x: Any, p: Any) -> tuple[float, float]:
    return (0.0, 1.0)


def _h(x: Any, p: Any) -> float:
    return x[0]


def _f_complex(x: Any, p: Any) -> Any:
    return (x[1], np.sqrt(x[0] - 1.0 + 0j))


_TABLE = {"k": 2.0}  # a Python dict: numba cannot type it as a global


def _f_dict(x: Any, p: Any) -> tuple[float, float]:
    return (x[1], -_TABLE["k"] * x[0])


def _f_fails(x: Any, p: Any) -> tuple[float, float]:
    """Fails at run time as p[0] says: 1, raises once x1 > 0.3; 2, divides by x1 (finite at
    the check point x = 0.1, inf at x0 = 0).  One function for both failures, so the two
    tests below share one kernel."""
    if p[0] == 1.0 and x[0] > 0.3:
        raise ValueError("x1 left the table of this model")
    if p[0] == 2.0:
        return (x[1], 1.0 / x[0])
    return (x[1], -x[0])


def _user_plant(f: Any, name: str, params: dict[str, float] | None = None) -> Plant:
    return Plant(
        name=name, n_states=2, f=f, g=_g, h=_h, params=params or {"k": 1.0}, relative_degree=2
    )


def test_a_plant_function_returning_complex_numbers_is_refused_by_check() -> None:
    plant = _user_plant(_f_complex, "cplx")
    with pytest.raises(PlantError, match=r"'cplx': f\(x, p\) returns complex numbers at x ="):
        plant.check()
    with pytest.raises(PlantError, match="returns complex numbers"):
        plant.compiled  # noqa: B018 - compiling checks first


def test_a_function_complex_only_in_numba_types_is_refused_by_typecheck() -> None:
    def f(x: Any, p: Any) -> Any:
        if x[0] > 5.0:
            return (x[1], 1j * x[0])
        return (x[1], -x[0])

    plant = _user_plant(f, "cplx2")
    plant.check()  # real at x = 0.1
    with pytest.raises(PlantError, match=r"'cplx2': f\(x, p\) returns complex numbers when comp"):
        plant.typecheck()


def test_check_requires_finite_values_at_the_initial_state() -> None:
    def f(x: Any, p: Any) -> tuple[float, float]:
        return (x[1], 1.0 / x[0])

    plant = _user_plant(f, "singular")
    plant.check()  # finite at the default point x = 0.1
    with np.errstate(divide="ignore"), pytest.raises(PlantError, match="not finite at the initial"):
        plant.check(np.array([0.0, 0.0]))
    with pytest.raises(PlantError, match=r"f\(x, p\) failed at state x = \[0.0, 0.0\]"):
        _user_plant(lambda x, p: (x[1], 1.0 / float(x[0])), "raises").check([0.0, 0.0])


def test_a_plant_function_numba_cannot_compile_is_a_plant_error_naming_it() -> None:
    plant = _user_plant(_f_dict, "dict")
    plant.check()  # fine in Python
    with pytest.raises(PlantError, match=r"'dict': numba cannot compile f\(x, p\): TypingError"):
        plant.typecheck()


def _simulate(plant: Plant, t_final: float = 1.0) -> Any:
    from aiofl.controller import Controller
    from aiofl.engine.simulation import simulate
    from aiofl.scenario import Reference, Scenario

    ctrl = Controller.from_structure(
        "LADRC",
        rho=2,
        values={"eso.omega0": 40.0, "sef.omega_c": 5.0, "td.omega": 10.0, "law.b0": 1.0},
    )
    scen = Scenario(reference=Reference(kind="step", amplitude=1.0), t_final=t_final)
    return simulate(plant, ctrl, scen, dt=1e-3)


def test_simulating_a_plant_numba_cannot_compile_is_a_plant_error(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setenv("AIOFL_NO_CACHE", "1")  # the type check runs before the kernel
    with pytest.raises(PlantError, match=r"numba cannot compile f\(x, p\).*dict"):
        _simulate(_user_plant(_f_dict, "dict_sim"))


@pytest.mark.slow
def test_a_plant_function_that_raises_at_run_time_names_the_function_and_the_state() -> None:
    with pytest.raises(PlantError) as err:
        _simulate(_user_plant(_f_fails, "fails_rt", {"mode": 1.0}))
    msg = str(err.value)
    assert "plant 'fails_rt': plant function f failed at state x = [" in msg
    assert "ValueError: x1 left the table of this model" in msg
    state = [float(v) for v in re.search(r"x = \[([^\]]*)\]", msg).group(1).split(",")]
    assert len(state) == 2 and state[0] > 0.3  # the condition that raised holds there


@pytest.mark.slow
def test_a_division_by_zero_at_run_time_is_a_diverged_member_with_its_time() -> None:
    plant = _user_plant(_f_fails, "fails_rt", {"mode": 2.0})
    res = _simulate(plant)
    assert res.failed and res.stopped_at is not None and 0.0 < res.stopped_at <= 1.0
    assert res.metrics is None  # no NaN table
