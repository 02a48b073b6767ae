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

_SPEC = importlib.util.spec_from_file_location(
    "fuzz_inputs", Path(__file__).resolve().parents[1] / "benchmarks" / "fuzz_inputs.py"
)
assert _SPEC is not None and _SPEC.loader is not None
fuzz = importlib.util.module_from_spec(_SPEC)
sys.modules.setdefault("fuzz_inputs", fuzz)
_SPEC.loader.exec_module(fuzz)

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
    if record["diverged"]:
        assert math.isfinite(record["diverged_at"])
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
