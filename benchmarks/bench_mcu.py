"""Code size, stack and instructions per step of the exported float controller on Cortex-M.

Run ``python benchmarks/bench_mcu.py`` (needs ``arm-none-eabi-gcc`` with newlib and
``qemu-system-arm``; Debian: ``apt-get install gcc-arm-none-eabi libnewlib-arm-none-eabi
qemu-system-arm``).  For each shipped scenario-1 and scenario-2 design (``--designs`` to
choose) it runs ``aiofl export DESIGN --ts TS --precision float``, compiles the controller for
a Cortex-M4F (``-mcpu=cortex-m4 -mthumb -mfpu=fpv4-sp-d16 -mfloat-abi=hard -Os``) and a
Cortex-M0+ (``-mcpu=cortex-m0plus -mthumb -Os``), and prints

* code size: ``text`` of the controller's object (arm-none-eabi-size: code and constant
  tables) + that of the default parameter instance (``aiofl_params.c``, read-only data);
  data and bss are 0 for every design,
* stack: bytes per call of the step function (``-fstack-usage``; library callees not
  counted),
* run-time calls the object makes (``arm-none-eabi-nm -u``): libm functions, and on the M0+
  libgcc's soft-float routines; any double-precision call (``__aeabi_d*``) is named,
* ITAE qemu/host: the 5-s closed loop of ``tests/firmware/loop.c`` on qemu's M4F against the
  same program built for the host (``=``: bit for bit; else the relative difference), with
  one implementation of the libm functions on both sides (``tests/firmware/mathf.c``) and
  with each side's own (newlib, glibc: they need not round alike),
* instructions per step: the first ``--steps`` samples of the closed loop of
  ``tests/firmware/loop.c`` (the controller and the SLFJM in float), recorded on the host and
  replayed on qemu (M4F: ``mps2-an386``; M0+ build: ``microbit``, a Cortex-M0) with an
  instruction trace (``-singlestep -d exec,nochain``): the count of each ``aiofl_step`` call,
  callees (libm, soft float) included: mean, and [min-max] when they differ.

qemu counts instructions, not cycles: it has no timing model of these cores and does not
model the M4's DWT cycle counter.  On a Cortex-M4 most integer and FPU instructions take one
cycle, loads 2, taken branches 2-4, VDIV/VSQRT 14, so cycles are roughly 1.2-1.6 x the count;
at 168 MHz, 200 instructions are ~1.5 us, 0.15 % of a 1 ms sample.  See
``tests/cortex_m.py`` for the methods, and ``tests/test_cortex_m.py`` for the checks.
"""

from __future__ import annotations

import argparse
import math
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from cortex_m import (  # type: ignore[import-not-found]
    M0P,
    M4F,
    build_host,
    compile_controller,
    export_float,
    link_firmware,
    missing_tools,
    run_host,
    run_qemu,
    signal_is_double,
    traced_instructions,
    write_replay,
)

DESIGNS = (
    "paper-s1-leso",
    "paper-s1-inleso",
    "retuned-s1-leso",
    "retuned-s1-inleso",
    "retuned-s1-ladrc",
    "frontier-s1-leso",
    "frontier-s1-inleso",
    "frontier-s1-ladrc",
    "assisted-s1-ladrc",
    "paper-s2-leso",
    "paper-s2-inleso",
    "retuned-s2-leso",
    "retuned-s2-inleso",
    "retuned-s2-ladrc",
    "frontier-s2-leso",
    "frontier-s2-inleso",
    "frontier-s2-ladrc",
    "assisted-s2-ladrc",
)


def _table(title: str, header: list[str], rows: list[list[str]]) -> None:
    widths = [max(len(str(c)) for c in col) for col in zip(header, *rows, strict=True)]
    print(f"\n{title}")
    print("  " + "  ".join(h.ljust(w) for h, w in zip(header, widths, strict=True)))
    print("  " + "  ".join("-" * w for w in widths))
    for row in rows:
        print("  " + "  ".join(str(c).ljust(w) for c, w in zip(row, widths, strict=True)))


def _calls(ctrl) -> str:
    """libm calls by name, double-precision ones with their call sites (``xN``), the
    number of libgcc's soft-float single-precision routines."""
    soft, double = ctrl.float_calls(), ctrl.double_calls()
    shown = [n for n in ctrl.undefined if n not in ("memset", "memcpy", *soft, *double)]
    shown += [f"{n.removeprefix('__aeabi_')}x{ctrl.call_sites.get(n, 0)}" for n in double]
    return " ".join([*shown, *([f"{len(soft)} __aeabi_f*"] if soft else [])]) or "-"


def _count(ctrl, include: Path, out: Path, steps: int, extra: dict[str, str]) -> str:
    """Mean [min-max] instructions per aiofl_step over the first ``steps`` closed-loop calls
    (replayed: ``write_replay`` has recorded y in the export's directory)."""
    defines = {"REPLAY": "1", "N_STEPS": str(steps), "N_COUNT": "1", **extra}
    elf = link_firmware(ctrl, include, out, defines, "replay")
    counts = traced_instructions(elf, ctrl.target.board, ("aiofl_step",), out)["aiofl_step"]
    counts = counts[:steps]
    lo, hi = min(counts), max(counts)
    mean = statistics.fmean(counts)
    return f"{mean:.0f}" if lo == hi else f"{mean:.0f} [{lo}-{hi}]"


def _plant_defines(design: str) -> dict[str, str]:
    """loop.c's plant for the design's scenario: its load inertia scale (scenario 2:
    J_l x 1.4; the load step at 10 s is beyond loop.c's 5 s)."""
    from aiofl.config import load_config

    scale = dict(load_config(design).scenario.plant_scale)
    if set(scale) - {"J_l"}:
        raise SystemExit(f"bench_mcu: loop.c scales J_l only, {design} scales {sorted(scale)}")
    return {"SCALE_JL": f"{float(scale['J_l'])!r}f"} if "J_l" in scale else {}


def _itae_match(sources: list[Path], d: Path, extra: dict[str, str]) -> list[str]:
    """ITAE of loop.c's 5-s closed loop on qemu's M4F against the host float build's: with
    one libm on both sides (tests/firmware/mathf.c), and with each side's own (newlib,
    glibc); "=" when bit for bit equal, else the relative difference."""
    ctrl = compile_controller(sources, M4F, d / "itae", extra)
    out = []
    for shared in (True, False):
        name = "shared" if shared else "own"
        elf = link_firmware(ctrl, sources[0].parent, d / "itae", extra, name, shared)
        host = run_host(build_host(sources, d / "itae", extra, shared))["itae"]
        got = run_qemu(elf, M4F.board)["itae"]
        if not (math.isfinite(host) and math.isfinite(got)):
            out.append("diverged")
        else:
            out.append("=" if got == host else f"{abs(got - host) / abs(host):.1e}")
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--designs", nargs="*", default=list(DESIGNS))
    ap.add_argument("--ts", type=float, default=1e-3)
    ap.add_argument("--steps", type=int, default=200, help="closed-loop steps traced")
    ap.add_argument("--no-count", action="store_true", help="sizes and stack only")
    ap.add_argument(
        "--float-signal",
        action="store_true",
        help="y and r as float at the API (-DAIOFL_SIGNAL_IS_FLOAT, the params API)",
    )
    args = ap.parse_args()
    reason = missing_tools()
    if reason:
        sys.exit(f"bench_mcu: {reason}")
    for tool in ("arm-none-eabi-gcc", "qemu-system-arm"):
        first = subprocess.run([tool, "--version"], capture_output=True, text=True).stdout
        print(f"{tool}: {first.splitlines()[0]}")
    rows, refused, notes = [], [], []
    with tempfile.TemporaryDirectory() as tmp:
        for design in args.designs:
            d = Path(tmp) / design
            try:
                warned: list[str] = []
                sources = export_float(design, args.ts, d / "export", warned)
                notes += [f"  {design}: {w.removeprefix('aiofl: ')}" for w in warned]
            except RuntimeError as exc:
                refused.append(f"  {design}: {str(exc).splitlines()[-1]}")
                continue
            extra = {"AIOFL_SIGNAL_IS_FLOAT": "1"} if args.float_signal else {}
            plant = _plant_defines(design)
            row = [design, *_itae_match(sources, d, {**extra, **plant})]
            if not args.no_count:
                k = write_replay(sources, d, args.steps, {**extra, **plant})
                if k is not None:
                    notes.append(
                        f"  {design}: loop.c's closed loop diverged (y not finite from k = {k})"
                    )
            if extra and not signal_is_double(sources):
                notes.append(f"  {design}: --float-signal: the export's signals are float")
            for target in (M4F, M0P):
                ctrl = compile_controller(sources, target, d / target.board, extra)
                step = next(v[0] for k, v in ctrl.stack.items() if k.endswith("_step"))
                row += [
                    f"{ctrl.text - ctrl.params_text}+{ctrl.params_text}",
                    str(step),
                    _calls(ctrl),
                ]
                if not args.no_count:
                    include = sources[0].parent
                    row.append(_count(ctrl, include, d / target.board, args.steps, extra))
            rows.append(row)
    per_target = ["code+params B", "stack B", "calls", *([] if args.no_count else ["insns/step"])]
    header = ["design", "ITAE qemu/host", "(own libm)"]
    header += [f"{t} {h}" for t in ("M4F", "M0+") for h in per_target]
    _table(
        f"float export at Ts = {args.ts:g} s"
        + (", float signals" if args.float_signal else "")
        + "; -Os; M4F: -mcpu=cortex-m4 -mfpu=fpv4-sp-d16 "
        "-mfloat-abi=hard; M0+: -mcpu=cortex-m0plus (soft float); insns/step: qemu "
        f"instruction trace of the first {args.steps} closed-loop steps, callees included",
        header,
        rows,
    )
    if refused:
        print("\nnot exported:")
        print("\n".join(refused))
    if notes:
        print(
            "\nnotes (aiofl export's warnings; loop.c: the SLFJM stepped in float, J_l scaled"
            " as in the design's scenario, scenario 1's reference):"
        )
        print("\n".join(notes))


if __name__ == "__main__":
    main()
