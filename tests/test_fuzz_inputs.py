"""Every input is refused with exit 2 or run to a result: hypothesis mutates the presets.

The mutations are the primitives of ``benchmarks/fuzz_inputs.py`` (drop, duplicate or
rename a key, a wrong type or a huge / tiny / negative / NaN / inf value, an inserted key,
the text cut at any point, an empty file), drawn here by hypothesis with a fixed seed
(``derandomize``) so a CI run is deterministic.  Each mutated config goes through the CLI
in-process (typer's ``CliRunner``):

* ``aiofl simulate CASE --out DIR --check`` (validation only) for every case;
* the full ``aiofl simulate CASE --out DIR`` for the ones that pass it, when the base is a
  preset of the SLFJM (one compiled kernel serves them all; presets are shortened to
  0.4 s so a run is cheap).

Asserted for both: exit status 0 or 2, no traceback, nothing in ``--out`` (and no staging
folder) after exit 2, and every exit-0 run's metrics finite or the run flagged diverged
with a finite time.  A few plant-file mutations that must be refused (a cut-off file, a
missing or renamed key, a wrong type) are checked to exit 2.
"""

from __future__ import annotations

import importlib.util
import json
import math
import sys
import tempfile
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from aiofl.cli.app import app


def _benchmark(name: str) -> Any:
    """A script of benchmarks/ loaded as a module (the fuzzers' cases and tables)."""
    path = Path(__file__).resolve().parents[1] / "benchmarks" / f"{name}.py"
    spec = importlib.util.spec_from_file_location(name, path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault(name, module)
    spec.loader.exec_module(module)
    return module


fuzz = _benchmark("fuzz_inputs")

BASES = fuzz.base_cases()
SLFJM_BASES = sorted(n for n, (text, _) in BASES.items() if 'plant = "slfjm"' in text)
OTHER_BASES = sorted(n for n in BASES if n not in SLFJM_BASES and n != "plant-file")

mutation = st.builds(
    fuzz.Mutation,
    kind=st.sampled_from(fuzz.MUTATION_KINDS),
    index=st.integers(0, 10_000),
    # bad values, and plausible ones (so that many mutated configs do run)
    literal=st.one_of(
        st.sampled_from(fuzz.BAD_LITERALS),
        st.floats(min_value=1e-3, max_value=1e4, allow_nan=False).map(repr),
    ),
    key=st.sampled_from(fuzz.EXTRA_KEYS),
)
mutations = st.lists(mutation, min_size=1, max_size=3)
FUZZ = settings(
    derandomize=True,
    database=None,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow],
)
"""Seeded (derandomised): the same cases on every run."""
runner = CliRunner()


def _invoke(workdir: Path, run_text: str, plant_text: str | None, *extra: str) -> Any:
    cfg = workdir / "case.toml"
    cfg.write_text(run_text, encoding="utf-8")
    if plant_text is not None:
        (workdir / "pend.toml").write_text(plant_text, encoding="utf-8")
    return runner.invoke(app, ["simulate", str(cfg), "--out", str(workdir / "out"), *extra])


def _check_outcome(res: Any, workdir: Path, *, ran: bool) -> None:
    """The properties every case must have, exit 0 or 2."""
    text = (res.stdout or "") + (res.stderr or "")
    if res.exception is not None and not isinstance(res.exception, SystemExit):
        raise res.exception  # a traceback: the test fails with it
    assert res.exit_code in (0, 2), text
    assert "Traceback" not in text
    out = workdir / "out"
    assert not [p.name for p in workdir.iterdir() if p.name.startswith(".out.")]
    if res.exit_code == 2 or not ran:
        assert not out.exists(), text  # refused or --check: nothing written
        if res.exit_code == 2:
            assert res.stderr.startswith("aiofl: error: ") and res.stderr.strip()
        return
    record = json.loads((out / "metrics.json").read_text(encoding="utf-8"))
    if record["failed"]:
        assert math.isfinite(record["stopped_at"])
    else:
        for key in ("itae", "isu", "iau", "opi"):
            assert isinstance(record[key], float) and math.isfinite(record[key]), record
    assert "nan" not in (out / "trajectory.csv").read_text(encoding="utf-8").lower()


def _run_case(base: str, muts: list[Any], *, full: bool) -> int:
    run_text, plant_text = fuzz.mutated_texts(base, muts)
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        res = _invoke(work, run_text, plant_text, "--check")
        _check_outcome(res, work, ran=False)
        if full and res.exit_code == 0:
            res = _invoke(work, run_text, plant_text)
            _check_outcome(res, work, ran=True)
        return res.exit_code


@pytest.mark.slow
@settings(FUZZ, max_examples=250)
@given(base=st.sampled_from(SLFJM_BASES), muts=mutations)
def test_mutated_slfjm_presets_are_refused_or_run(base: str, muts: list[Any]) -> None:
    event(f"exit {_run_case(base, muts, full=True)}")  # --hypothesis-show-statistics


plausible = st.lists(
    st.builds(
        fuzz.Mutation,
        kind=st.just("replace"),
        index=st.integers(0, 10_000),
        literal=st.floats(min_value=1e-3, max_value=1e4, allow_nan=False).map(repr),
    ),
    min_size=1,
    max_size=2,
)


@pytest.mark.slow
@settings(FUZZ, max_examples=80)
@given(base=st.sampled_from(SLFJM_BASES), muts=plausible)
def test_plausible_values_run_finite_or_diverged(base: str, muts: list[Any]) -> None:
    """Numbers in range for many fields: most such configs run, and many diverge."""
    event(f"exit {_run_case(base, muts, full=True)}")


@settings(FUZZ, max_examples=100)
@given(base=st.sampled_from(OTHER_BASES), muts=mutations)
def test_mutated_presets_of_other_plants_are_refused_or_valid(base: str, muts: list[Any]) -> None:
    event(f"exit {_run_case(base, muts, full=False)}")


def _plant_cut_points() -> list[int]:
    _, plant = BASES["plant-file"]
    assert plant is not None
    # cut anywhere before the last parameter (g): the file always lacks a symbol it uses
    return [0, 1, *range(7, plant.rindex("\ng = "), 9)]


@pytest.mark.parametrize("cut", _plant_cut_points())
def test_a_cut_off_plant_file_is_refused(cut: int) -> None:
    assert _run_case("plant-file", [fuzz.Mutation("truncate", index=cut)], full=False) == 2


@pytest.mark.parametrize(
    "mut",
    [
        fuzz.Mutation("empty"),
        fuzz.Mutation("drop", index=2),  # f
        fuzz.Mutation("drop", index=4),  # h
        fuzz.Mutation("rename", index=1),  # states -> states_x
        fuzz.Mutation("rename", index=2),  # f -> F
        fuzz.Mutation("duplicate", index=3),  # g twice: malformed TOML
        fuzz.Mutation("replace", index=4, literal="true"),  # h = true
        fuzz.Mutation("replace", index=1, literal="[]"),  # no states
        fuzz.Mutation("replace", index=5, literal='"1"'),  # m = "1"
        fuzz.Mutation("replace", index=2, literal="3"),  # f = 3
        fuzz.Mutation("drop_header"),  # the parameters land in the top table
    ],
    ids=lambda m: m.describe(),
)
def test_plant_file_mutations_are_refused(mut: Any) -> None:
    assert _run_case("plant-file", [mut], full=False) == 2


def test_the_mutations_do_what_they_say() -> None:
    """The primitives themselves (a broken mutator would make the fuzz test vacuous)."""
    text = 'a = 1\n[t]\nb = 2.0\nc = "x"\n'
    M = fuzz.Mutation
    assert fuzz.apply_mutation(text, M("replace", index=1, literal="nan")).splitlines()[2] == (
        "b = nan"
    )
    assert "b = 2.0" not in fuzz.apply_mutation(text, M("drop", index=1))
    assert fuzz.apply_mutation(text, M("duplicate", index=0)).count("a = 1") == 2
    assert "B = 2.0" in fuzz.apply_mutation(text, M("rename", index=4))  # even: upper case
    assert "a_x = 1" in fuzz.apply_mutation(text, M("rename", index=3))  # odd: suffix
    assert fuzz.apply_mutation(text, M("insert", key="dt", literal="1e-9")).splitlines()[2] == (
        "dt = 1e-9"
    )
    assert fuzz.apply_mutation(text, M("truncate", index=7)) == text[:7]
    assert fuzz.apply_mutation(text, M("empty")) == ""
    assert "[t]" not in fuzz.apply_mutation(text, M("drop_header"))
    short = fuzz.shorten(BASES["retuned-s2-leso"][0])
    assert "t_final = 0.4\n" in short and "disturbance_time = 0.2\n" in short
    assert "\nt_final = 12.0" in short  # the [tune] table is left as it was


EDGE_LITERALS = ("5e-324", "1e-12", "1e300", "inf", "-inf", "nan", "-1", "0", "true", '"50 "')


@pytest.mark.parametrize("literal", EDGE_LITERALS)
def test_every_key_of_a_preset_with_an_edge_value_is_refused_or_valid(literal: str) -> None:
    """A systematic sweep beside the random one: each key of a preset that sets most of
    them (scenario 3: noise; scenario 2: disturbance and plant change), in turn, set to
    one edge value, through the CLI's validation."""
    for base in ("paper-s3-inleso", "retuned-s2-leso"):
        head = BASES[base][0].split("\n[tune]")[0]  # [tune] is not read by simulate
        n_keys = len(fuzz._key_lines(head.splitlines()))
        for index in range(n_keys):
            _run_case(base, [fuzz.Mutation("replace", index=index, literal=literal)], full=False)


# ---------------------------------------------- [controller.discrete], [uncertainty], [tune]
# The tables and commands added after the fuzzer (sampled controllers, C export, robustness,
# robust / multi-objective tuning): each table is mutated on its own, appended to a short
# SLFJM preset, and driven through its command on cheap settings.
# the tables and the short preset are the table fuzzer's own (benchmarks/fuzz_tables.py)
tables = _benchmark("fuzz_tables")
SHORT, DISCRETE, UNCERTAINTY, TUNE = tables.SHORT, tables.DISCRETE, tables.UNCERTAINTY, tables.TUNE
TABLE_LITERALS = (
    *fuzz.BAD_LITERALS,
    "1e9",  # draws = 1e9 (a float) and as an integer below
    "1000000000",
    "0.00015",  # ts not a multiple of dt
    "1.0",  # ts > t_final
    "-0.001",
    '"euler"',
    '"fhan"',
    '"nsga2"',
    '"ga"',
    '["itae"]',
    '["itae", "isu", "iae", "ise"]',
    '["itae:cvar", "isu:worst"]',
    "[\"__import__('os')\"]",
    "[\"__import__('os').system('true') <= 1\"]",
    '["isu <= 1e999"]',
    '["isu <= nan"]',
    '["isu < 1"]',
    '["itae:cvar <= 1e-300"]',
    "{ uniform = 0.9999999 }",
    "{ uniform = 1.0 }",
    "{ normal = 0.5 }",
    "{ normal = 0.6 }",
    "{ log_uniform = [1e-300, 1e300] }",
    "{ log_uniform = [2.0, 0.5] }",
    "{ log_uniform = [0.0, 1.0] }",
    "[1e-4, 1e-4]",
    "[0.4, 1.0]",
    "[0.0, inf]",
    '{ draws = 1000000000, aggregate = "cvar", alpha = 0.9 }',
    '{ draws = 2, aggregate = "cvar", alpha = 1.0 }',
    '{ draws = 2, aggregate = "worst" }',
    '{ draws = 2, aggregate = "median" }',
)
TABLE_KEYS = (
    "ts",
    "delay",
    "h0",
    "y_quantum",
    "u_quantum",
    "draws",
    "seed",
    "noise_variance",
    "robust",
    "objectives",
    "constraints",
    "choose",
    "algorithm",
    "J_h",
)
table_mutations = st.lists(
    st.builds(
        fuzz.Mutation,
        # mostly a replaced value (half of them plausible numbers, so many cases run)
        kind=st.sampled_from(("replace",) * 8 + fuzz.MUTATION_KINDS),
        index=st.integers(0, 10_000),
        literal=st.one_of(
            st.sampled_from(TABLE_LITERALS),
            st.floats(min_value=1e-4, max_value=2.0, allow_nan=False).map(repr),
        ),
        key=st.sampled_from(TABLE_KEYS),
    ),
    min_size=1,
    max_size=2,
)
#: files a tune run refused *after* it ran (no feasible design) keeps: the checkpoint, so
#: ``--resume --generations N`` can carry on (docs/guide/tuning.md, Checkpoint and resume)
RESUMABLE = frozenset({"checkpoint.npz", ".aiofl-output"})


def _strict_json(path: Path) -> Any:
    def refuse(token: str) -> Any:
        raise AssertionError(f"{path.name} holds {token}")

    return json.loads(path.read_text(encoding="utf-8"), parse_constant=refuse)


def _command(
    table_text: str, command: str, *extra: str, ran_ok: frozenset[str] = frozenset()
) -> Any:
    """Run ``aiofl COMMAND case.toml [--out DIR] EXTRA`` on ``SHORT + table_text`` and check
    the properties every outcome must have; returns the result."""
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        cfg = work / "case.toml"
        cfg.write_text(table_text, encoding="utf-8")
        out = work / "out"
        args = [command, str(cfg)]
        if command != "analyze":
            args += ["--out", str(out)]
        res = runner.invoke(app, [*args, *extra])
        text = (res.stdout or "") + (res.stderr or "")
        if res.exception is not None and not isinstance(res.exception, SystemExit):
            raise res.exception
        assert res.exit_code in (0, 2), text
        assert "Traceback" not in text and "Warning" not in text, text
        assert not [p.name for p in work.iterdir() if p.name.startswith(".out.")]
        if res.exit_code == 2:
            assert res.stderr.startswith("aiofl: error: ") and res.stderr.strip(), text
            left = {p.name for p in out.iterdir()} if out.exists() else set()
            assert left <= ran_ok, (left, text)
            return res
        if "--check" in extra or command == "analyze":
            assert not out.exists()
            return res
        for path in out.iterdir():
            if path.suffix == ".json":
                _strict_json(path)
        if command == "simulate":
            record = _strict_json(out / "metrics.json")
            if record["failed"]:
                assert math.isfinite(record["stopped_at"])
            else:
                assert all(math.isfinite(record[k]) for k in ("itae", "isu", "iau", "opi"))
            assert "nan" not in (out / "trajectory.csv").read_text(encoding="utf-8").lower()
        elif command == "export":
            c_text = (out / "aiofl_controller.c").read_text(encoding="utf-8")
            assert "nan" not in c_text.lower().replace("aiofl_", "")
        return res


def _mutate(table: str, muts: list[Any]) -> str:
    for m in muts:
        table = fuzz.apply_mutation(table, m)
    return table


@settings(FUZZ, max_examples=150)
@given(muts=table_mutations, extra=st.sampled_from([(), ("--ts", "0.002"), ("--ts", "1e-300")]))
def test_mutated_discrete_table_simulates_and_exports_or_is_refused(
    muts: list[Any], extra: tuple[str, ...]
) -> None:
    text = SHORT + _mutate(DISCRETE, muts)
    res = _command(text, "simulate", "--check")
    if res.exit_code == 0:
        event(f"simulate exit {_command(text, 'simulate').exit_code}")
    event(f"export exit {_command(text, 'export', '--precision', 'float', *extra).exit_code}")


@settings(FUZZ, max_examples=60)
@given(
    muts=table_mutations,
    tolerance=st.sampled_from(["0.1", "0", "-1", "nan", "inf", "1e300", "5e-324"]),
)
def test_mutated_discrete_table_sampling_analysis_or_is_refused(
    muts: list[Any], tolerance: str
) -> None:
    """``aiofl analyze --sampling --json``: exit 0 with strict JSON (null, never NaN) or 2."""
    text = SHORT + _mutate(DISCRETE, muts)
    res = _command(text, "analyze", "--sampling", "--json", "--tolerance", tolerance)
    if res.exit_code == 0:
        json.loads(res.stdout, parse_constant=lambda c: pytest.fail(f"stdout holds {c}"))
    event(f"analyze exit {res.exit_code}")


@settings(FUZZ, max_examples=100)
@given(muts=table_mutations)
def test_mutated_uncertainty_table_runs_robustness_or_is_refused(muts: list[Any]) -> None:
    text = SHORT + DISCRETE + _mutate(UNCERTAINTY, muts)
    event(f"robustness exit {_command(text, 'robustness', '--draws', '2').exit_code}")


@settings(FUZZ, max_examples=80)
@given(muts=table_mutations)
def test_mutated_tune_table_tunes_one_generation_or_is_refused(muts: list[Any]) -> None:
    text = SHORT + _mutate(UNCERTAINTY.replace("ts = [0.0005, 0.002]\n", "") + TUNE, muts)
    event(f"tune exit {_command(text, 'tune', '--quiet', ran_ok=RESUMABLE).exit_code}")


@pytest.mark.parametrize(
    ("table", "field"),
    [
        (DISCRETE.replace("u_quantum = 0.0", "u_quantum = 5e-324"), "u_quantum"),
        (DISCRETE.replace("y_quantum = 0.0", "y_quantum = 1e-300"), "y_quantum"),
        (DISCRETE.replace("u_quantum = 0.0", "u_quantum = -1"), "u_quantum"),
        (DISCRETE.replace("ts = 0.001", "ts = 0.00015"), "ts"),
        (DISCRETE.replace("ts = 0.001", "ts = 2.0"), "ts"),
        (DISCRETE + "draws = 3\n", "draws"),
    ],
)
def test_bad_discrete_values_are_refused_naming_the_field(table: str, field: str) -> None:
    """Regression: a subnormal quantum (1/q = inf) used to run and write NaN rows."""
    res = _command(SHORT + table, "simulate", "--check")
    assert res.exit_code == 2 and f"controller.discrete.{field}" in res.stderr, res.stderr


@pytest.mark.parametrize(
    ("ts", "needle"),
    [
        ("1e-300", "controller.discrete.ts = 1e-300"),
        ("inf", "--ts = inf; allowed: 0 < ts <= 1"),
        ("2", "--ts = 2.0; allowed: 0 < ts <= 1"),
        ("nan", "--ts = nan"),
    ],
)
def test_export_refuses_an_absurd_sample_time_without_a_warning(ts: str, needle: str) -> None:
    """Regression: --ts 1e-300 printed numpy's overflow RuntimeWarning before the error."""
    res = _command(SHORT + DISCRETE, "export", "--ts", ts)
    assert res.exit_code == 2 and needle in res.stderr, res.stderr


@pytest.mark.parametrize(
    ("old", "new", "field"),
    [
        ('"isu <= 1e3"', "\"__import__('os')\"", "tune.constraints"),
        ('"isu <= 1e3"', '"isu <= 1e999"', "tune.constraints"),
        ('"isu <= 1e3"', '"isu < 1"', "tune.constraints"),
        ("draws = 2,", "draws = 1000000000,", "robust"),
        ('["itae", "isu"]', '["itae"]', "objectives"),
        ("draws = 3", "draws = 1e9", "uncertainty.draws"),
    ],
)
def test_hostile_tune_values_are_refused_before_any_run(old: str, new: str, field: str) -> None:
    text = SHORT + UNCERTAINTY.replace("ts = [0.0005, 0.002]\n", "") + TUNE
    assert old in text
    res = _command(text.replace(old, new, 1), "tune", "--quiet")
    assert res.exit_code == 2 and field in res.stderr, res.stderr


def test_robustness_refuses_absurd_draws() -> None:
    res = _command(SHORT + DISCRETE + UNCERTAINTY, "robustness", "--draws", "1000000000")
    assert res.exit_code == 2 and "--draws" in res.stderr, res.stderr
