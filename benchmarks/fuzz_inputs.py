"""Fuzzing ``aiofl simulate`` with mutated configs: how many are run, refused, crash or hang.

Run ``python benchmarks/fuzz_inputs.py [--cases 1500] [--seed 0] [--timeout 30]``.

Each case takes a shipped preset (``src/aiofl/presets/*.toml``, its horizon shortened to
:data:`SHORT_T_FINAL` seconds so a case that runs is cheap) or a small symbolic plant file
with its run config, applies one to three text mutations (:func:`mutate`: drop, duplicate or
rename a key, replace a value by a wrong type or a huge / tiny / negative / NaN / inf number,
insert a key, truncate the text at a random point, empty the file) and runs
``aiofl simulate CASE.toml --out DIR`` in-process through typer's ``CliRunner``, in a
worker process with an address-space limit (so a run that allocates terabytes fails there
instead of on the machine) and a per-case timeout (a case past it is a *hang*: the worker is
killed and replaced).  Every case is classified as

* ``exit 0``: ran; ``metrics.json`` holds finite metrics or says ``diverged`` with a time;
* ``exit 2``: refused with one message and nothing in ``--out``;
* ``other``: anything else (a traceback, another exit status, a partial ``--out``, a NaN
  in an exit-0 result), listed with its mutation so it can be replayed;
* ``hang``: no answer within ``--timeout`` seconds.

Everything is seeded (``--seed``): the same command draws the same cases.  The mutation
primitives are shared with ``tests/test_fuzz_inputs.py``, where hypothesis draws them.
Wall-clock figures depend on the machine's load; no assertion is made here.
"""

from __future__ import annotations

import argparse
import json
import math
import multiprocessing as mp
import os
import random
import re
import shutil
import signal
import sys
import tempfile
import time
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]

#: horizon [s] the presets are shortened to before mutation (events scaled with it)
SHORT_T_FINAL = 0.4

#: a small symbolic plant file (pendulum) and a run config that names it
PLANT_FILE = """\
name = "pendulum_fuzz"
states = ["theta", "theta_dot"]
f = ["theta_dot", "-g/l*sin(theta) - c/(m*l**2)*theta_dot"]
g = ["0", "1/(m*l**2)"]
h = "theta"
[params]
m = 1.0
l = 0.5
c = 0.1
g = 9.81
"""

PLANT_RUN = """\
name = "pendulum-run"
plant = "pend.toml"
[scenario]
t_final = 0.4
[scenario.reference]
kind = "step"
amplitude = 0.5
[controller]
structure = "LADRC"
n_feedback = 2
[controller.eso]
omega0 = 60.0
[controller.td]
omega = 8.0
[controller.sef]
omega_c = 8.0
[controller.law]
b0 = 4.0
[simulation]
dt = 1e-3
"""

#: replacement values: wrong types, and numbers far outside / at the edge of any range
BAD_LITERALS: tuple[str, ...] = (
    "true",
    "false",
    '"50 "',
    '"1e-3"',
    '""',
    '"slfjm"',
    "[]",
    "[1.0, 2.0]",
    '["a"]',
    "{ a = 1 }",
    "{}",
    "1979-05-27",
    "nan",
    "inf",
    "-inf",
    "0",
    "0.0",
    "-1",
    "-1e-3",
    "1e300",
    "-1e300",
    "1.7976931348623157e308",
    "5e-324",
    "1e-12",
    "1e-7",
    "1e7",
    "9999",
    "1e-9",
    "99999999999999999999999",
    "9223372036854775807",
    "-9223372036854775808",
    "3",
    "0.5",
    "2",
)

#: keys a preset may leave out, inserted by the ``insert`` mutation (with a BAD_LITERAL)
EXTRA_KEYS: tuple[str, ...] = (
    "noise_hold",
    "noise_variance",
    "noise_seed",
    "decimation",
    "divergence_threshold",
    "parameter_change_time",
    "disturbance_time",
    "disturbance_amplitude",
    "t_step",
    "x0",
    "rho",
    "n_feedback",
    "dt",
    "t_final",
    "u_max",
    "sample_dt",
    "samples",
    "plant",
    "name",
    "structure",
    "kind",
)

MUTATION_KINDS: tuple[str, ...] = (
    "replace",
    "drop",
    "duplicate",
    "rename",
    "insert",
    "truncate",
    "empty",
    "drop_header",
)

_KEY_LINE = re.compile(r"^(\s*)([A-Za-z0-9_'.\"-]+)(\s*=\s*)(.*)$")


@dataclass(frozen=True)
class Mutation:
    """One text mutation: ``kind`` and where/what (indices wrap around the text)."""

    kind: str
    index: int = 0
    literal: str = "true"
    key: str = "dt"

    def describe(self) -> str:
        return f"{self.kind}(index={self.index}, literal={self.literal!r}, key={self.key!r})"


def shorten(text: str, t_final: float = SHORT_T_FINAL) -> str:
    """Scale a preset's horizon to ``t_final`` (event times scaled with it; ``[tune]`` left)."""
    scale: list[float] = []

    def horizon(m: re.Match[str]) -> str:
        scale.append(t_final / float(m.group(2)))
        return f"{m.group(1)}{t_final!r}"

    head, sep, tune = text.partition("\n[tune]")
    head = re.sub(r"^(t_final\s*=\s*)([0-9.eE+-]+)", horizon, head, count=1, flags=re.M)
    if scale:
        for key in ("disturbance_time", "parameter_change_time", "t_step"):
            head = re.sub(
                rf"^({key}\s*=\s*)([0-9.eE+-]+)",
                lambda m: f"{m.group(1)}{float(m.group(2)) * scale[0]!r}",
                head,
                flags=re.M,
            )
    return head + sep + tune


def _key_lines(lines: list[str]) -> list[int]:
    return [i for i, ln in enumerate(lines) if _KEY_LINE.match(ln) and ln.lstrip()[:1] != "#"]


def apply_mutation(text: str, m: Mutation) -> str:
    """``text`` with mutation ``m`` applied (a no-op where it does not apply)."""
    if m.kind == "empty":
        return ""
    if m.kind == "truncate":
        return text[: m.index % (len(text) + 1)]
    lines = text.splitlines()
    keyed = _key_lines(lines)
    headers = [i for i, ln in enumerate(lines) if ln.lstrip().startswith("[")]
    if m.kind == "drop_header" and headers:
        del lines[headers[m.index % len(headers)]]
        return "\n".join(lines) + "\n"
    if m.kind == "insert":
        at = headers[m.index % len(headers)] + 1 if headers else 0
        lines.insert(at, f"{m.key} = {m.literal}")
        return "\n".join(lines) + "\n"
    if not keyed:
        return text
    i = keyed[m.index % len(keyed)]
    match = _KEY_LINE.match(lines[i])
    assert match is not None
    indent, key, eq, _value = match.groups()
    if m.kind == "replace":
        lines[i] = f"{indent}{key}{eq}{m.literal}"
    elif m.kind == "drop":
        del lines[i]
    elif m.kind == "duplicate":
        lines.insert(i, lines[i])
    elif m.kind == "rename":
        new_key = f"{key}_x" if m.index % 2 else key.upper()
        lines[i] = f"{indent}{new_key}{eq}{_value}"
    return "\n".join(lines) + "\n"


def base_cases() -> dict[str, tuple[str, str | None]]:
    """name -> (run config text, plant file text or None): every preset, shortened, and
    the pendulum plant-file pair (``plant-file`` mutates the plant, ``plant-run`` the run)."""
    from aiofl.config import list_presets, preset_text

    cases: dict[str, tuple[str, str | None]] = {
        name: (shorten(preset_text(name)), None) for name in list_presets()
    }
    cases["plant-run"] = (PLANT_RUN, PLANT_FILE)
    cases["plant-file"] = (PLANT_RUN, PLANT_FILE)
    return cases


def draw_mutations(rng: random.Random) -> list[Mutation]:
    """One to three mutations drawn from ``rng`` (the benchmark's generator)."""
    out = []
    for _ in range(rng.choice((1, 1, 1, 2, 3))):
        kind = rng.choices(MUTATION_KINDS, weights=(10, 3, 2, 2, 3, 2, 0.3, 1))[0]
        out.append(
            Mutation(
                kind=kind,
                index=rng.randrange(10_000),
                literal=rng.choice(BAD_LITERALS),
                key=rng.choice(EXTRA_KEYS),
            )
        )
    return out


def mutated_texts(base: str, mutations: list[Mutation]) -> tuple[str, str | None]:
    """(run config text, plant file text) of base case ``base`` after ``mutations``."""
    run, plant = base_cases()[base]
    for m in mutations:
        if base == "plant-file":
            assert plant is not None
            plant = apply_mutation(plant, m)
        else:
            run = apply_mutation(run, m)
    return run, plant


# ------------------------------------------------------------------------ checking
def _finite_or_diverged(record: dict[str, Any]) -> bool:
    if record.get("diverged"):
        t = record.get("diverged_at")
        return isinstance(t, (int, float)) and math.isfinite(t)
    vals = [record.get(k) for k in ("itae", "isu", "iau", "opi")]
    return all(isinstance(v, (int, float)) and math.isfinite(v) for v in vals)


def run_case(run_text: str, plant_text: str | None, workdir: Path) -> tuple[str, str]:
    """Run one case through the CLI in this process: (class, detail)."""
    from typer.testing import CliRunner

    from aiofl.cli.app import app

    workdir.mkdir(parents=True, exist_ok=True)
    cfg = workdir / "case.toml"
    cfg.write_text(run_text, encoding="utf-8")
    if plant_text is not None:
        (workdir / "pend.toml").write_text(plant_text, encoding="utf-8")
    out = workdir / "out"
    res = CliRunner().invoke(app, ["simulate", str(cfg), "--out", str(out)])
    text = (res.stdout or "") + (res.stderr or "")
    if res.exception is not None and not isinstance(res.exception, SystemExit):
        exc = res.exception
        return "other", f"{type(exc).__name__}: {str(exc)[:300]}"
    if "Traceback" in text:
        return "other", "traceback in output: " + text[-300:]
    stale = [p.name for p in workdir.iterdir() if p.name.startswith(".out.")]
    if stale:
        return "other", f"left behind: {stale}"
    if res.exit_code == 2:
        if out.exists() and any(out.iterdir()):
            return "other", f"exit 2 but --out has {sorted(p.name for p in out.iterdir())}"
        return "exit2", text.strip().splitlines()[-1][:300] if text.strip() else ""
    if res.exit_code == 0:
        metrics = out / "metrics.json"
        if not metrics.is_file():
            return "other", "exit 0 without metrics.json"
        record = json.loads(metrics.read_text(encoding="utf-8"))
        if not _finite_or_diverged(record):
            return "other", f"exit 0 with non-finite metrics: {record}"
        return "exit0", "diverged" if record.get("diverged") else "ok"
    return "other", f"exit {res.exit_code}: {text[-300:]}"


def _worker(conn: Any, mem_limit: int) -> None:
    import resource

    resource.setrlimit(resource.RLIMIT_AS, (mem_limit, mem_limit))
    while True:
        job = conn.recv()
        if job is None:
            return
        idx, run_text, plant_text, workdir = job
        try:
            verdict = run_case(run_text, plant_text, Path(workdir))
        except BaseException as exc:  # the harness itself must not stop
            verdict = ("other", f"harness: {type(exc).__name__}: {exc}"[:300])
        shutil.rmtree(workdir, ignore_errors=True)
        conn.send((idx, *verdict))


class _Worker:
    def __init__(self, mem_limit: int) -> None:
        ctx = mp.get_context("spawn")
        self.conn, child = ctx.Pipe()
        self.proc = ctx.Process(target=_worker, args=(child, mem_limit), daemon=True)
        self.proc.start()

    def kill(self) -> None:
        if self.proc.pid is not None and self.proc.is_alive():
            os.kill(self.proc.pid, signal.SIGKILL)
        self.proc.join(5)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=1500)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--timeout", type=float, default=30.0, help="per case [s]")
    ap.add_argument("--mem-gb", type=float, default=6.0, help="worker address-space limit")
    ap.add_argument("--json", type=Path, default=None, help="write every case's verdict here")
    args = ap.parse_args(argv)

    rng = random.Random(args.seed)
    names = list(base_cases())
    counts: Counter[str] = Counter()
    cases: list[dict[str, Any]] = []
    t0 = time.perf_counter()
    worker = _Worker(int(args.mem_gb * 2**30))
    with tempfile.TemporaryDirectory(prefix="aiofl-fuzz-") as tmp:
        for idx in range(args.cases):
            base = rng.choice(names)
            muts = draw_mutations(rng)
            run_text, plant_text = mutated_texts(base, muts)
            worker.conn.send((idx, run_text, plant_text, str(Path(tmp) / f"case{idx}")))
            if worker.conn.poll(args.timeout):
                _, verdict, detail = worker.conn.recv()
            else:
                verdict, detail = "hang", f"no answer in {args.timeout:g} s"
                worker.kill()
                worker = _Worker(int(args.mem_gb * 2**30))
            counts[verdict] += 1
            entry = {
                "case": idx,
                "base": base,
                "mutations": [m.describe() for m in muts],
                "verdict": verdict,
                "detail": detail,
            }
            cases.append(entry)
            if verdict in ("other", "hang"):
                print(f"[{idx}] {verdict}: {base} {entry['mutations']}\n    {detail}", flush=True)
            if (idx + 1) % 100 == 0:
                print(f"... {idx + 1} cases, {dict(counts)}", file=sys.stderr, flush=True)
        worker.conn.send(None)
        worker.proc.join(10)
        worker.kill()
    elapsed = time.perf_counter() - t0
    print(
        f"\nfuzz_inputs: seed {args.seed}, {args.cases} tried: exit 0 = {counts['exit0']}, "
        f"exit 2 = {counts['exit2']}, other = {counts['other']}, hangs = {counts['hang']} "
        f"(timeout {args.timeout:g} s) in {elapsed:.0f} s; load average {os.getloadavg()[0]:.1f}"
    )
    if args.json is not None:
        args.json.write_text(json.dumps(cases, indent=1) + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
