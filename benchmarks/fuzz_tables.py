"""Fuzzing the tables and commands added after ``fuzz_inputs.py``: how many cases run, are
refused, crash, hang, leave files behind, or get text into the generated C.

Run ``python benchmarks/fuzz_tables.py [--cases 300] [--campaign all] [--seed 0]``.

Four campaigns, each on a short SLFJM preset (``retuned-s1-leso`` cut to 0.4 s):

``discrete``
    ``[controller.discrete]`` mutated (the mutations of ``fuzz_inputs.py``: replaced values,
    dropped / duplicated / renamed / inserted keys, truncation) and run by ``aiofl simulate``
    (sometimes ``--ts``) and ``aiofl export``.
``uncertainty``
    ``[uncertainty]`` mutated and run by ``aiofl robustness --draws 2``.
``export``
    ``aiofl export`` of a config whose ``name`` and ``description`` are hostile text (C
    comment closers, backslash-newline, trigraphs, ``#error``, newlines, NUL, bidirectional
    controls, 10 000 characters) and whose path runs through a hostile folder name.  Every
    exported file is compiled (``gcc -std=c99 -fsyntax-only -Wall -Wextra -Werror
    -trigraphs``) and stripped of its comments (``gcc -fpreprocessed -E``): the marker
    ``PWNED`` left in the code is *code reaching the generated C*.
``nsga2``
    ``[tune]`` of NSGA-II with mutated ``objectives`` / ``constraints`` strings (Python
    injection, format strings, Unicode digits, 1e999, ...) run by ``aiofl tune --check``
    and, for one case in four, a one-generation run; a file ``PWNED`` appearing in the
    working folder is code executed.

Every case runs through typer's ``CliRunner`` in a worker process (address-space limit,
per-case timeout: past it the case is a *hang* and the worker is replaced) with the worker's
working folder set to the case folder, and is classified

* ``exit0``: ran, its JSON outputs strict (no NaN), the C files compile cleanly;
* ``exit2``: refused with one ``aiofl: error:`` message, ``--out`` not created;
* ``other``: a traceback, another exit status, non-strict JSON, C that fails to compile;
* ``leftover``: a staging / trash folder, or files in ``--out`` after a refusal (a tune
  refused after it ran may keep its checkpoint: docs/guide/tuning.md, Checkpoint and resume);
* ``code``: the marker reached the C code, or an injected command ran;
* ``hang``: no answer within ``--timeout`` seconds.

Everything is seeded (``--seed``).  Wall-clock figures depend on the machine's load.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import multiprocessing as mp
import os
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
_SPEC = importlib.util.spec_from_file_location("fuzz_inputs", HERE / "fuzz_inputs.py")
assert _SPEC is not None and _SPEC.loader is not None
fuzz = importlib.util.module_from_spec(_SPEC)
sys.modules.setdefault("fuzz_inputs", fuzz)
_SPEC.loader.exec_module(fuzz)

SHORT = fuzz.base_cases()["retuned-s1-leso"][0].split("\n[tune]")[0]
DISCRETE = """
[controller.discrete]
ts = 0.001
delay = 0
y_quantum = 0.0
u_quantum = 0.0
eso = "zoh"
td = "fhan"
h0 = 0.002
"""
UNCERTAINTY = """
[uncertainty]
draws = 3
seed = 0
ts = [0.0005, 0.002]
noise_variance = [0.0, 1e-6]
[uncertainty.parameters]
J_l = { uniform = 0.2 }
K_s = { normal = 0.05 }
R_m = { log_uniform = [0.5, 2.0] }
"""
TUNE = """
[tune]
algorithm = "nsga2"
objectives = ["itae", "isu"]
constraints = ["isu <= 1e3", "stable_fraction >= 1"]
choose = "knee"
t_final = 0.2
population = 4
generations = 1
seed = 1
robust = { draws = 2, aggregate = "cvar", alpha = 0.9 }
[tune.parameters]
'eso.omega0' = { lo = 10.0, hi = 100.0, log = true }
"""
TABLE_LITERALS: tuple[str, ...] = (
    *fuzz.BAD_LITERALS,
    "1e9",
    "1000000000",
    "0.00015",
    "1.0",
    "0.04",
    "0.05",
    "-0.001",
    '"euler"',
    '"zoh"',
    '"fhan"',
    "1",
    "0.1",
    "1e-6",
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
    "[0.001, 0.002, 0.003]",
)
#: values that fit a key (half the replacements draw from here, so many cases run)
PLAUSIBLE: dict[str, tuple[str, ...]] = {
    "ts": ("0.0005", "0.001", "0.002", "0.01", "0.04", "0.05", "0.1", "0.0001"),
    "delay": ("0", "1"),
    "h0": ("0.001", "0.002", "0.01", "0.1", "0.2", "1e-6", "5e-7"),
    "y_quantum": ("0.0", "0.0015339807878856412", "1e-12", "0.1"),
    "u_quantum": ("0.0", "0.01", "1.0"),
    "eso": ('"zoh"', '"euler"'),
    "td": ('"fhan"', '"euler"'),
    "draws": ("1", "2", "3", "64"),
    "seed": ("0", "1", "9223372036854775807"),
    "noise_variance": ("[0.0, 1e-6]", "[1e-6, 1e-6]", "[0.0, 0.0]"),
    "J_l": ("{ uniform = 0.5 }", "{ normal = 0.1 }", "{ log_uniform = [0.9, 1.1] }"),
    "K_s": ("{ uniform = 0.99 }", "{ normal = 0.3 }"),
    "R_m": ("{ log_uniform = [0.1, 10.0] }", "{ uniform = 0.0 }"),
}
TABLE_KEYS = ("ts", "delay", "h0", "y_quantum", "u_quantum", "eso", "td", "draws", "seed", "J_h")

#: objective / constraint strings for the nsga2 campaign (PWNED: an injected command ran)
NSGA_VALID: tuple[str, ...] = ("itae", "isu", "iae", "itae:cvar", "isu:worst")
NSGA_VALID_CONSTRAINTS: tuple[str, ...] = (
    "isu <= 1e3",
    "stable_fraction >= 1",
    "isu:worst <= 25",
    "itae:cvar <= 10",
)
NSGA_STRINGS: tuple[str, ...] = (
    "ise",
    "iau",
    "opi",
    "itae:worst",
    "itae:median",
    "stable_fraction",
    "itae:",
    ":cvar",
    "ITAE",
    " itae ",
    "itae\n",
    "__import__('os').system('touch PWNED')",
    "open('PWNED', 'w')",
    "eval('1')",
    "{0.__class__}",
    "%s%s%n",
    "itae; import os",
    "itae" * 2000,
    "\u0000",
    "\u202eitae",
    "isu <= 1e3",
    "isu <= 1e999",
    "isu <= nan",
    "isu <= inf",
    "isu <= -1e300",
    "isu < 1",
    "isu >= 1",
    "isu == 1",
    "isu <= 1_000",
    "isu <= \u0661\u0660",  # Arabic-Indic digits: float() reads them
    "isu <= 1e3 <= 2",
    "isu <= __import__('os').system('touch PWNED')",
    "stable_fraction >= 1",
    "stable_fraction >= 2",
    "stable_fraction >= -1",
    "itae:cvar <= 1e-300",
    "isu:worst <= 25",
    "<=",
    "",
)

#: fragments of hostile text for names, descriptions and folder names (PWNED: the marker)
HOSTILE: tuple[str, ...] = (
    "*/ int PWNED = 1; /*",
    "*/\n#error PWNED\n/*",
    "\\\nint PWNED;",
    "*\\\n/ int PWNED;",
    "??/\nint PWNED;",
    "??=error PWNED",
    '\n#include "PWNED"\n',
    "\r#define PWNED 1\r",
    "// PWNED\n int PWNED;",
    "\u2028int PWNED;\u2029",
    "\u202e;DENWP tni\u202c",
    "\u0000PWNED",
    "\t\v\f PWNED",
    '"; PWNED; "',
    "' PWNED '",
    "$(touch PWNED)",
    "`touch PWNED`",
    "%n%s PWNED",
    "caf\u00e9 \U0001f600",
    "PWNED " * 2000,
    "plain design",
)
#: folder names the config is put in for the export campaign (a path goes into the comment)
HOSTILE_DIRS: tuple[str, ...] = (
    "cfg",
    "x */ int PWNED; ",
    "x\\",
    "y\n#error PWNED",
    "??/",
    "*",
    "#PWNED",
    "\u202ePWNED",
    " lead and trail ",
)


def _toml_string(text: str) -> str:
    """``text`` as a TOML basic string (JSON's escapes are TOML's)."""
    return json.dumps(text, ensure_ascii=False)


def _key_at(table: str, index: int) -> str:
    """The key of the line a mutation with ``index`` replaces (as apply_mutation picks it)."""
    lines = table.splitlines()
    keyed = fuzz._key_lines(lines)
    if not keyed:
        return ""
    m = fuzz._KEY_LINE.match(lines[keyed[index % len(keyed)]])
    return m.group(2) if m else ""


def _mutate(table: str, rng: random.Random) -> tuple[str, list[str]]:
    """One or two mutations of ``table``; half the replaced values fit their key."""
    muts = []
    for _ in range(rng.choice((1, 1, 2))):
        kind = rng.choice(("replace",) * 24 + fuzz.MUTATION_KINDS)
        index = rng.randrange(10_000)
        literal = rng.choice(TABLE_LITERALS)
        fits = PLAUSIBLE.get(_key_at(table, index))
        if kind == "replace" and fits and rng.random() < 0.5:
            literal = rng.choice(fits)
        elif rng.random() < 0.2:
            literal = repr(10 ** rng.uniform(-5, 0.5))
        muts.append(fuzz.Mutation(kind, index, literal, key=rng.choice(TABLE_KEYS)))
    for m in muts:
        table = fuzz.apply_mutation(table, m)
    return table, [m.describe() for m in muts]


def draw_case(campaign: str, rng: random.Random) -> dict[str, Any]:
    """One case: the config text, its folder, the command and what was drawn."""
    folder, extra, drawn = "cfg", [], []
    if campaign == "discrete":
        table, drawn = _mutate(DISCRETE, rng)
        text = SHORT + table
        command = rng.choice(("simulate", "simulate", "export"))
        if rng.random() < 0.3:
            extra = ["--ts", rng.choice(("0.002", "0.04", "1e-300", "0.00015"))]
    elif campaign == "uncertainty":
        table, drawn = _mutate(UNCERTAINTY, rng)
        text, command, extra = SHORT + DISCRETE + table, "robustness", ["--draws", "2"]
    elif campaign == "export":
        name = "".join(rng.choice(HOSTILE) for _ in range(rng.randint(1, 3)))
        desc = "".join(rng.choice(HOSTILE) for _ in range(rng.randint(1, 3)))
        folder = rng.choice(HOSTILE_DIRS)
        head = SHORT.split("\n", 1)
        body = "\n".join(ln for ln in head[1].splitlines() if not ln.startswith("name ="))
        body = "\n".join(ln for ln in body.splitlines() if not ln.startswith("description ="))
        text = f"name = {_toml_string(name)}\ndescription = {_toml_string(desc)}\n{head[0]}\n"
        text += body + "\n" + DISCRETE
        command = "export"
        extra = rng.choice(([], ["--precision", "float"]))
        drawn = [f"name={name[:60]!r}", f"description={desc[:60]!r}", f"folder={folder!r}"]
    elif campaign == "nsga2":

        def pick(valid: tuple[str, ...]) -> str:  # one hostile string in about three
            return rng.choice(valid if rng.random() < 0.7 else NSGA_STRINGS)

        objectives = [pick(NSGA_VALID) for _ in range(rng.choice((1, 2, 2, 2, 3)))]
        constraints = [pick(NSGA_VALID_CONSTRAINTS) for _ in range(rng.choice((0, 1, 2)))]
        tune = TUNE.replace('["itae", "isu"]', "[" + ", ".join(map(_toml_string, objectives)) + "]")
        tune = tune.replace(
            '["isu <= 1e3", "stable_fraction >= 1"]',
            "[" + ", ".join(map(_toml_string, constraints)) + "]",
        )
        text = SHORT + UNCERTAINTY.replace("ts = [0.0005, 0.002]\n", "") + tune
        command = "tune"
        extra = ["--quiet"] if rng.random() < 0.25 else ["--check"]
        drawn = [f"objectives={[o[:40] for o in objectives]}", f"constraints={constraints}"]
    else:
        raise ValueError(campaign)
    return {"text": text, "folder": folder, "command": command, "extra": extra, "drawn": drawn}


# ------------------------------------------------------------------------ checking
def _strict_json(path: Path) -> str | None:
    bad: list[str] = []
    json.loads(path.read_text(encoding="utf-8"), parse_constant=bad.append)
    return f"{path.name} holds {bad[0]}" if bad else None


def _c_verdict(out: Path) -> tuple[str, str] | None:
    """('code', ...) if PWNED reached the code, ('other', ...) if the C does not compile."""
    c_file = out / "aiofl_controller.c"
    if shutil.which("gcc") is None:
        return None
    flags = ["-std=c99", "-Wall", "-Wextra", "-Werror", "-trigraphs", "-I", str(out)]
    res = subprocess.run(
        ["gcc", *flags, "-fsyntax-only", str(c_file)], capture_output=True, text=True
    )
    if res.returncode != 0:
        return "other", "gcc: " + res.stderr[-300:]
    for path in sorted(out.glob("*.[ch]")):
        code = subprocess.run(
            ["gcc", "-std=c99", "-trigraphs", "-fpreprocessed", "-dD", "-E", "-P", str(path)],
            capture_output=True,
            text=True,
        )
        if "PWNED" in code.stdout or "DENWP" in code.stdout:
            return "code", f"marker outside a comment in {path.name}"
    return None


def run_case(case: dict[str, Any], workdir: Path) -> tuple[str, str]:
    """Run one case through the CLI in this process: (class, detail)."""
    from typer.testing import CliRunner

    from aiofl.cli.app import app

    folder = workdir / case["folder"]
    folder.mkdir(parents=True, exist_ok=True)
    cfg = folder / "case.toml"
    cfg.write_text(case["text"], encoding="utf-8")
    out = workdir / "out"
    args = [case["command"], str(cfg), *case["extra"]]
    if "--check" not in case["extra"]:
        args += ["--out", str(out)]
    os.chdir(workdir)
    res = CliRunner().invoke(app, args)
    text = (res.stdout or "") + (res.stderr or "")
    if (workdir / "PWNED").exists():
        return "code", "an injected command ran (PWNED created)"
    if res.exception is not None and not isinstance(res.exception, SystemExit):
        exc = res.exception
        return "other", f"{type(exc).__name__}: {str(exc)[:300]}"
    if "Traceback" in text:
        return "other", "traceback in output: " + text[-300:]
    stale = [p.name for p in workdir.iterdir() if p.name.startswith(".out.")]
    if stale:
        return "leftover", f"left behind: {stale}"
    if res.exit_code == 2:
        keep = {"checkpoint.npz", ".aiofl-output"} if case["command"] == "tune" else set()
        left = {p.name for p in out.iterdir()} - keep if out.exists() else set()
        if left:
            return "leftover", f"exit 2 but --out has {sorted(left)}"
        if not res.stderr.startswith("aiofl: error: "):
            return "other", f"exit 2 without one error message: {text[-300:]}"
        return "exit2", " ".join(res.stderr.split())[:300]
    if res.exit_code != 0:
        return "other", f"exit {res.exit_code}: {text[-300:]}"
    if out.exists():
        for path in out.glob("*.json"):
            problem = _strict_json(path)
            if problem:
                return "other", problem
        if case["command"] == "export":
            verdict = _c_verdict(out)
            if verdict is not None:
                return verdict
        if case["command"] == "simulate":
            record = json.loads((out / "metrics.json").read_text(encoding="utf-8"))
            if not fuzz._finite_or_diverged(record):
                return "other", f"exit 0 with non-finite metrics: {record}"
    return "exit0", "warning" if "warning" in res.stderr else "ok"


def _worker(conn: Any, mem_limit: int) -> None:
    import resource

    resource.setrlimit(resource.RLIMIT_AS, (mem_limit, mem_limit))
    while True:
        job = conn.recv()
        if job is None:
            return
        idx, case, workdir = job
        try:
            verdict = run_case(case, Path(workdir))
        except BaseException as exc:  # the harness itself must not stop
            verdict = ("other", f"harness: {type(exc).__name__}: {exc}"[:300])
        os.chdir(HERE)
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


CAMPAIGNS = ("discrete", "uncertainty", "export", "nsga2")
VERDICTS = ("exit0", "exit2", "other", "leftover", "code", "hang")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=300, help="per campaign")
    ap.add_argument("--campaign", choices=(*CAMPAIGNS, "all"), default="all")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--timeout", type=float, default=120.0, help="per case [s]")
    ap.add_argument("--mem-gb", type=float, default=6.0, help="worker address-space limit")
    ap.add_argument("--json", type=Path, default=None, help="write every case's verdict here")
    args = ap.parse_args(argv)

    campaigns = CAMPAIGNS if args.campaign == "all" else (args.campaign,)
    limit = int(args.mem_gb * 2**30)
    cases: list[dict[str, Any]] = []
    summary = []
    worker = _Worker(limit)
    with tempfile.TemporaryDirectory(prefix="aiofl-fuzz-tables-") as tmp:
        for campaign in campaigns:
            rng = random.Random(f"{args.seed}-{campaign}")
            counts: Counter[str] = Counter()
            t0 = time.perf_counter()
            for idx in range(args.cases):
                case = draw_case(campaign, rng)
                worker.conn.send((idx, case, str(Path(tmp) / f"{campaign}{idx}")))
                if worker.conn.poll(args.timeout):
                    _, verdict, detail = worker.conn.recv()
                else:
                    verdict, detail = "hang", f"no answer in {args.timeout:g} s"
                    worker.kill()
                    worker = _Worker(limit)
                counts[verdict] += 1
                entry = {"campaign": campaign, "case": idx, "verdict": verdict, "detail": detail}
                cases.append({**entry, "command": case["command"], "drawn": case["drawn"]})
                if verdict not in ("exit0", "exit2"):
                    print(f"[{campaign} {idx}] {verdict}: {case['drawn']}\n    {detail}")
                if (idx + 1) % 50 == 0:
                    print(f"... {campaign}: {idx + 1} cases, {dict(counts)}", file=sys.stderr)
            seconds = time.perf_counter() - t0
            figures = ", ".join(f"{v} = {counts[v]}" for v in VERDICTS)
            summary.append(f"{campaign}: {args.cases} tried: {figures} in {seconds:.0f} s")
        worker.conn.send(None)
        worker.proc.join(10)
        worker.kill()
    print(f"\nfuzz_tables: seed {args.seed}, timeout {args.timeout:g} s per case")
    for line in summary:
        print("  " + line)
    print(f"load average {os.getloadavg()[0]:.1f}")
    if args.json is not None:
        args.json.write_text(json.dumps(cases, indent=1) + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
