"""Hostile plant files: how ``aiofl analyze FILE --json`` ends on each (seeded corpus).

Run ``python benchmarks/fuzz_plant_files.py`` (options: ``--seed``, ``--random N``,
``--timeout S``, ``--jobs J``, ``--keep DIR``, ``--verbose``).  The script writes a corpus of
symbolic-plant TOML files into a temporary folder:

* fixed hostile classes: power towers (``10**10**10``), large integer powers
  (``(x1+1)**200``), deep nesting of parentheses and calls, thousands of unary minus signs,
  1,000 states or parameters, divisions by zero and other non-finite constants (``1/0``,
  ``log(0)``, ``1e400``, ``exp(1000)``), complex constants (``sqrt(-1)``), huge integer
  literals, very long sums, expansion bombs, forbidden syntax (attribute access, lambdas,
  subscripts, strings), Lie-derivative growth over long chains, wrong types of fields;
* ``--random`` seeded mutations of the shipped symbolic plant specs
  (:data:`aiofl.plants.library.SPECS`): an expression replaced by a random one, wrapped
  in a random power, edited character by character, a parameter set to a non-finite or
  non-numeric value, an entry dropped.

Each file is analysed in its own subprocess (``python -m aiofl analyze FILE --json``) with a
wall-clock ``--timeout``; the tally counts tried / exit 0 / exit 2 / other (any other exit
status, or a traceback on stderr) / hangs (timeout).  An exit-0 answer must be valid JSON
with no NaN or infinity in it; one that is not counts as "other".  Wall-clock times depend
on the machine's load; no assertion is made on them.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import random
import subprocess
import sys
import tempfile
import time
from collections import Counter
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

PENDULUM: dict[str, Any] = {
    "name": "fuzz",
    "states": ["x1", "x2"],
    "f": ["x2", "-g*sin(x1) - c*x2"],
    "g": ["0", "b"],
    "h": "x1",
    "params": {"g": 9.81, "c": 0.1, "b": 4.0},
}


def _toml_value(val: Any) -> str:
    if isinstance(val, bool):
        return "true" if val else "false"
    if isinstance(val, str):
        return json.dumps(val)  # a TOML basic string is a JSON string for these characters
    if isinstance(val, float):
        if math.isnan(val):
            return "nan"
        if math.isinf(val):
            return "inf" if val > 0 else "-inf"
        return repr(val)
    if isinstance(val, int):
        return str(val)
    if isinstance(val, (list, tuple)):
        return "[" + ", ".join(_toml_value(v) for v in val) + "]"
    raise TypeError(f"cannot write {val!r} as TOML")


def to_toml(spec: dict[str, Any]) -> str:
    """A plant spec as TOML text (top-level keys first, then ``[params]``/``[states]``)."""
    lines, tables = [], []
    for key, val in spec.items():
        if isinstance(val, dict):
            tables.append((key, val))
        else:
            lines.append(f"{key} = {_toml_value(val)}")
    for key, table in tables:
        lines.append(f"[{key}]")
        lines.extend(f"{k} = {_toml_value(v)}" for k, v in table.items())
    return "\n".join(lines) + "\n"


def _with(**changes: Any) -> dict[str, Any]:
    spec = json.loads(json.dumps(PENDULUM))
    spec.update(changes)
    return spec


def _f2(expr: str) -> dict[str, Any]:
    """The pendulum with its second drift entry replaced by ``expr``."""
    return _with(f=["x2", expr])


def _chain(n: int, link: str) -> dict[str, Any]:
    """x_i' = link(x_i, x_{i+1}), x_n' = u: relative degree n from y = x1."""
    states = [f"x{i}" for i in range(1, n + 1)]
    f = [link.format(a=states[i], b=states[i + 1]) for i in range(n - 1)] + ["0"]
    return {
        "name": f"chain{n}",
        "states": states,
        "f": f,
        "g": ["0"] * (n - 1) + ["1"],
        "h": "x1",
        "params": {"k": 1.0},
    }


def fixed_cases() -> list[tuple[str, str]]:
    """(label, TOML text) of the fixed hostile classes."""
    cases: list[tuple[str, dict[str, Any] | str]] = []
    add = cases.append
    # power towers and large integer powers
    for e in (
        "10**10**10",
        "9**9**9",
        "2**2**2**2**2",
        "x1**10**10",
        "(x1+1)**200",
        "(x1+1)**-200",
        "x1**100000",
        "((x1+1)**8)**8",
        "((x1+1)**16)**16",
        "(x1+x2+1)**100",
        "(x1 + x2 + 1)**30 * (x1 - x2)**30",
        "2**100000",
        "(-2)**(2**70)",
        "10.0**400.0",
        "x1**1e300",
        "2.0**1e10",
        "1e300**1e300",
        "exp(1000)",
        "exp(exp(exp(exp(10))))",
        "sinh(1e6)",
    ):
        add((f"power: {e}", _f2(e)))
    # deep nesting
    for depth in (50, 100, 300, 1000):
        add((f"nesting: {depth} parentheses", _f2("(" * depth + "x1" + ")" * depth)))
    for depth in (30, 100, 400):
        add((f"nesting: {depth} sin()", _f2("sin(" * depth + "x1" + ")" * depth)))
    add(("nesting: 20 exp()", _f2("exp(" * 20 + "x1" + ")" * 20)))
    add(("nesting: 60 products", _f2("x1*(" * 60 + "x2" + ")" * 60)))
    # unary signs
    for k in (200, 2000, 20000):
        add((f"unary: {k} minus signs", _f2("-" * k + "x1")))
    add(("unary: 1000 '+-'", _f2("+-" * 1000 + "x1")))
    # sizes: states, parameters, text
    for n in (1000, 100, 40):
        states = [f"s{i}" for i in range(n)]
        add(
            (
                f"size: {n} states",
                {
                    "name": "many",
                    "states": states,
                    "f": [states[(i + 1) % n] for i in range(n)],
                    "g": ["0"] * (n - 1) + ["1"],
                    "h": "s0",
                    "params": {"k": 1.0},
                },
            )
        )
    add(
        (
            "size: 1000 params",
            _with(params={**PENDULUM["params"], **{f"q{i}": 1.0 for i in range(1000)}}),
        )
    )
    add(("size: sum of 5000 terms", _f2("+".join(["x1"] * 5000))))
    add(("size: sum of 20000 terms", _f2("+".join(["x1*x2"] * 20000))))
    add(("size: product of 3000 factors", _f2("*".join(["(x1+x2)"] * 3000))))
    add(("size: 200k characters", _f2("x1" + " " * 200_000)))
    add(("size: 5000-digit literal", _f2("1" + "0" * 5000)))
    add(("size: 400-digit literal times x1", _f2("1" + "0" * 400 + "*x1")))
    add(("size: 5000-digit float", _f2("1" + "0" * 5000 + ".0")))
    # expansion and Lie-derivative growth
    add(("expand: (x1+x2+b+c+1)**40", _f2("(x1+x2+b+c+1)**40")))
    add(("expand: h = (x1+x2+1)**60", _with(h="(x1+x2+1)**60")))
    add(("lie: chain of 12 sin links", _chain(12, "sin({a})*{b} + cos({b})")))
    add(("lie: chain of 8 exp links", _chain(8, "exp({a}*{b})")))
    add(("lie: chain of 20 linear links", _chain(20, "{b} - k*{a}")))
    add(("lie: chain of 30 linear links", _chain(30, "{b} - k*{a}")))
    add(("lie: chain of 6 quartic links", _chain(6, "{b} + ({a}+{b})**4")))
    # division by zero and non-finite constants
    for e in (
        "1/0",
        "x1/0",
        "0/0",
        "log(0)",
        "1/(x1-x1)",
        "x1 + 1e400",
        "-1e400*x2",
        "1e308*10",
        "exp(1000)*x1",
        "0*1e400",
        "atan2(0, 0)",
        "1/(1/0)",
    ):
        add((f"nonfinite: f[2] = {e}", _f2(e)))
    add(("nonfinite: g[2] = 1/0", _with(g=["0", "1/0"])))
    add(("nonfinite: g[2] = 0/0", _with(g=["0", "0/0"])))
    add(("nonfinite: h = x1 + 1/0", _with(h="x1 + 1/0")))
    add(("nonfinite: bd = [0, log(0)]", _with(bd=["0", "log(0)"])))
    add(("nonfinite: param = inf", _with(params={"g": math.inf, "c": 0.1, "b": 4.0})))
    add(("nonfinite: param = nan", _with(params={"g": math.nan, "c": 0.1, "b": 4.0})))
    add(("nonfinite: param b = 0", _with(params={"g": 9.81, "c": 0.1, "b": 0.0})))
    add(("nonfinite: param 1e308", _with(params={"g": 1e308, "c": 1e308, "b": 1e308})))
    # complex constants
    for e in ("sqrt(-1)", "log(-1)", "asin(2)", "(-1)**0.5", "acos(5)*x1", "(-8)**(1/3)"):
        add((f"complex: f[2] = {e}", _f2(e)))
    add(("complex: g[2] = sqrt(-4)", _with(g=["0", "sqrt(-4)"])))
    # forbidden syntax and wrong types
    for e in (
        "__import__('os').system('true')",
        "x1.real",
        "lambda: 0",
        "x1 if x2 else 0",
        "x1[0]",
        "'abc'",
        "x1 @ x2",
        "x1 // 2",
        "x1 % 2",
        "[x1]",
        "x1 < x2",
        "True",
        "sin",
        "sin(x1, x2)",
        "min(x1)",
        "f(x1)",
        "x1 ^ 2",
        "(x1 := 3)",
        "",
        "   ",
        "x1 +",
        "1j*x1",
    ):
        add((f"syntax: f[2] = {e!r}", _f2(e)))
    add(("types: f = 5", _with(f=5)))
    add(("types: f entries are numbers", _with(f=[1, 2.5])))
    add(("types: h is a list", _with(h=["x1", "x2"])))
    add(("types: states = 3", _with(states=3)))
    add(("types: states empty", _with(states=[], f=[], g=[])))
    add(("types: param is a string", _with(params={"g": "9.81", "c": 0.1, "b": 4.0})))
    add(("types: param is a bool", _with(params={"g": True, "c": 0.1, "b": 4.0})))
    add(("types: equilibrium of strings", _with(equilibrium=["a", "b"])))
    add(("types: equilibrium inf", _with(equilibrium=[math.inf, 0.0])))
    add(("names: state named sin", _with(states=["sin", "x2"], f=["x2", "x1"], h="sin")))
    add(("names: dunder", _with(states=["__class__", "x2"])))
    add(("names: unicode state", _with(states=["θ", "x2"], f=["x2", "-θ"], h="θ")))
    add(("eta: wrong eta", _with(eta=["x1**200"])))
    add(("eta: eta 1/0", _with(eta=["1/0"])))
    add(("no input", _with(g=["0", "0"])))
    add(("no input reaches output", _with(f=["0", "x2"], g=["0", "1"])))
    add(("empty file", ""))
    add(("truncated file", 'name = "x"\nstates = ["x1", '))
    add(("binary junk", "\x00\x01\x02 = = ="))
    return [(lbl, c if isinstance(c, str) else to_toml(c)) for lbl, c in cases]


_ATOMS = ["x1", "x2", "x3", "g", "c", "b", "pi", "0", "1", "2", "0.5", "1e3", "-1", "1e308"]
_FUNCS = ["sin", "cos", "tan", "exp", "log", "sqrt", "abs", "sign", "tanh", "asin", "atan"]
_CHARS = [*"x123+-*/() .e^,%@[]", "**", "sin(", "exp(", "log(", "0", "1/0", "pi"]


def random_expression(rng: random.Random, depth: int = 0) -> str:
    """A random expression over the atoms, functions and operators (bounded depth)."""
    r = rng.random()
    if depth > 4 or r < 0.3:
        return rng.choice(_ATOMS)
    if r < 0.55:
        op = rng.choice(["+", "-", "*", "/", "**"])
        return f"({random_expression(rng, depth + 1)}){op}({random_expression(rng, depth + 1)})"
    if r < 0.8:
        fn = rng.choice(_FUNCS)
        return f"{fn}({random_expression(rng, depth + 1)})"
    if r < 0.9:
        return f"-({random_expression(rng, depth + 1)})"
    return f"({random_expression(rng, depth + 1)})**{rng.choice([2, 3, 10, 65, 200, -3, 0.5])}"


def mutate_text(rng: random.Random, text: str) -> str:
    """A few random character edits (insert, delete, replace) of ``text``."""
    chars = list(text)
    for _ in range(rng.randint(1, 4)):
        pos = rng.randint(0, len(chars))
        kind = rng.random()
        if kind < 0.4:
            chars.insert(pos, rng.choice(_CHARS))
        elif kind < 0.7 and chars:
            del chars[min(pos, len(chars) - 1)]
        elif chars:
            chars[min(pos, len(chars) - 1)] = rng.choice(_CHARS)
    return "".join(chars)


def random_cases(rng: random.Random, count: int) -> list[tuple[str, str]]:
    """``count`` seeded mutations of the shipped symbolic plant specs."""
    from aiofl.plants.library import SPECS

    out = []
    names = sorted(SPECS)
    for k in range(count):
        base = json.loads(json.dumps(SPECS[rng.choice(names)]))
        base.pop("name", None)
        base["name"] = f"mut{k}"
        fields = [key for key in ("f", "g", "bd") if key in base]
        key = rng.choice([*fields, "h", "params"])
        how = rng.choice(["replace", "power", "edit", "edit", "drop", "value"])
        if key == "params" or how == "value":
            pname = rng.choice(sorted(base["params"]))
            val = rng.choice(
                [math.inf, -math.inf, math.nan, 0.0, 1e308, -1e-308, "1", True, 1e-320]
            )
            base["params"][pname] = val
            label = f"param {pname} = {val!r}"
        elif key == "h":
            new = {
                "replace": lambda s: random_expression(rng),
                "power": lambda s: f"({s})**{rng.choice([2, 7, 65, 300, -64, 1e9])}",
                "edit": lambda s: mutate_text(rng, s),
                "drop": lambda s: "0",
            }[how](base["h"])
            base["h"] = new
            label = f"h {how}: {new[:60]!r}"
        else:
            vec = list(base[key])
            i = rng.randrange(len(vec))
            if how == "drop":
                del vec[i]
                label = f"{key}[{i + 1}] dropped"
            else:
                vec[i] = {
                    "replace": lambda s: random_expression(rng),
                    "power": lambda s: f"({s})**{rng.choice([2, 7, 65, 300, -64, 1e9])}",
                    "edit": lambda s: mutate_text(rng, s),
                }[how](vec[i])
                label = f"{key}[{i + 1}] {how}: {vec[i][:60]!r}"
            base[key] = vec
        out.append((f"mutation {k}: {label}", to_toml(base)))
    return out


def _limit_memory(gigabytes: float) -> Any:
    """A ``preexec_fn`` capping the child's address space (a power tower must not take the
    shared machine's memory); exceeding it is a MemoryError, counted as "other"."""

    def apply() -> None:
        import resource

        cap = int(gigabytes * 2**30)
        resource.setrlimit(resource.RLIMIT_AS, (cap, cap))

    return apply


def run_one(path: Path, timeout: float, memory_gb: float) -> tuple[str, float, str]:
    """Run ``aiofl analyze path --json``; (outcome, seconds, last line of stderr)."""
    t0 = time.perf_counter()
    cmd = [sys.executable, "-m", "aiofl", "analyze", str(path), "--json"]
    try:
        proc = subprocess.run(
            cmd,
            capture_output=True,
            text=True,
            timeout=timeout,
            check=False,
            preexec_fn=_limit_memory(memory_gb),
        )
    except subprocess.TimeoutExpired:
        return "hang", time.perf_counter() - t0, f"no answer in {timeout:g} s"
    dt = time.perf_counter() - t0
    err = proc.stderr.strip()
    first = err.splitlines()[-1] if err else ""
    if "Traceback (most recent call last)" in err:
        return "other", dt, f"traceback: {first[:200]}"
    if proc.returncode == 0:
        try:
            json.loads(proc.stdout, parse_constant=_refuse_constant)
        except ValueError as exc:
            return "other", dt, f"exit 0 with bad JSON: {exc}"
        return "exit 0", dt, ""
    if proc.returncode == 2:
        return "exit 2", dt, first[:200]
    return "other", dt, f"exit {proc.returncode}: {first[:200]}"


def _refuse_constant(name: str) -> Any:
    raise ValueError(f"non-finite number {name} in the JSON")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=8)
    parser.add_argument("--random", type=int, default=40, help="number of random mutations")
    parser.add_argument("--timeout", type=float, default=30.0, help="seconds per file")
    parser.add_argument("--jobs", type=int, default=1, help="files analysed at once")
    parser.add_argument("--memory-gb", type=float, default=4.0, help="address-space cap")
    parser.add_argument("--keep", type=Path, default=None, help="write the corpus here")
    parser.add_argument("--verbose", action="store_true", help="one line per file")
    args = parser.parse_args()

    rng = random.Random(args.seed)
    corpus = fixed_cases() + random_cases(rng, args.random)
    with tempfile.TemporaryDirectory() as tmp:
        folder = args.keep or Path(tmp)
        folder.mkdir(parents=True, exist_ok=True)
        paths = []
        for i, (_, text) in enumerate(corpus):
            path = folder / f"plant_{i:03d}.toml"
            path.write_text(text, encoding="utf-8")
            paths.append(path)
        load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
        print(
            f"{len(corpus)} plant files (seed {args.seed}), timeout {args.timeout:g} s, "
            f"{args.jobs} at once; load average {load:.2f}"
        )
        t0 = time.perf_counter()
        with ThreadPoolExecutor(max_workers=max(1, args.jobs)) as pool:
            results = list(pool.map(lambda p: run_one(p, args.timeout, args.memory_gb), paths))
        wall = time.perf_counter() - t0
    tally = Counter(outcome for outcome, _, _ in results)
    slowest = max(results, key=lambda r: r[1])
    for (label, _), (outcome, dt, msg) in zip(corpus, results, strict=True):
        if args.verbose or outcome in ("other", "hang"):
            print(f"  {outcome:7s} {dt:6.2f}s  {label[:70]:70s}  {msg[:140]}")
    print(
        f"tried {len(corpus)} / exit 0 {tally['exit 0']} / exit 2 {tally['exit 2']} / "
        f"other {tally['other']} / hangs {tally['hang']}   "
        f"(slowest {slowest[1]:.1f} s; {wall:.0f} s in all)"
    )


if __name__ == "__main__":
    main()
