"""Cross-compile an exported controller for Cortex-M, run it on qemu, count its instructions.

Shared by ``tests/test_cortex_m.py`` and ``benchmarks/bench_mcu.py``.  The firmware sources
are in ``tests/firmware``: a bare-metal start with ARM semihosting (``startup.c``,
``semihost.h``), one linker script for the two qemu boards (``cortex_m.ld``) and the closed
loop (``loop.c``: the exported controller and the SLFJM stepped by RK4 in float, built for the
target and, with ``-DHOST``, for the host).

Targets: a Cortex-M4F (``mps2-an386``, the MPS2 AN386 FPGA image; hard float, FPv4-SP) and a
Cortex-M0+ (built ``-mcpu=cortex-m0plus``, soft float; run on qemu's ``microbit``, a
Cortex-M0 (ARMv6-M, the same instruction set)).

Instruction counts (qemu models no cycle timing of the M4 and no DWT cycle counter):

* ``-icount shift=0`` makes qemu's virtual clock advance 1 ns per executed instruction; the
  AN386's SysTick runs on its 25 MHz system clock, so one SysTick tick is 40 instructions.
  ``loop.c`` reads SysTick around ``N_COUNT`` controller steps and around the same loop
  calling a trivial function: (ticks_step - ticks_base) * 40 / N_COUNT instructions.
* ``-singlestep -d exec,nochain`` (one instruction per translation block, each logged when
  executed) traces every executed instruction's address: the exact count of each call, from
  the step function's entry to the return address after its caller's ``bl``, callees
  included.
"""

from __future__ import annotations

import math
import os
import re
import shutil
import struct
import subprocess
from dataclasses import dataclass, field
from pathlib import Path

FIRMWARE = Path(__file__).resolve().parent / "firmware"
OWN_SOURCES = ("loop.c", "startup.c", "mathf.c")  # compiled by the harness, not part of an export
COMMON = ("-std=c99", "-ffp-contract=off", "-Wall", "-Wextra", "-Werror")
SYSTICK_INSNS = 40  # instructions per SysTick tick: 1 ns each (-icount shift=0), 25 MHz clock
STEP = "aiofl_step"  # the default prefix's step function


@dataclass(frozen=True)
class Target:
    name: str
    cpu_flags: tuple[str, ...]
    board: str  # the qemu machine that runs it


M4F = Target(
    "Cortex-M4F",
    ("-mcpu=cortex-m4", "-mthumb", "-mfpu=fpv4-sp-d16", "-mfloat-abi=hard"),
    "mps2-an386",
)
M0P = Target("Cortex-M0+", ("-mcpu=cortex-m0plus", "-mthumb"), "microbit")
TARGETS = (M4F, M0P)
TOOLS = ("arm-none-eabi-gcc", "arm-none-eabi-size", "arm-none-eabi-nm", "arm-none-eabi-objdump")


def missing_tools() -> str | None:
    """Why the Cortex-M tests cannot run here (a tool not on PATH), or None."""
    missing = [t for t in (*TOOLS, "qemu-system-arm", "cc") if shutil.which(t) is None]
    install = (
        "(Debian: apt-get install gcc-arm-none-eabi libnewlib-arm-none-eabi qemu-system-arm; "
        ".ci/run installs them)"
    )
    if missing:
        return f"not on PATH: {', '.join(missing)} {install}"
    libc = subprocess.run(
        ["arm-none-eabi-gcc", "-print-file-name=libc.a"], capture_output=True, text=True
    ).stdout.strip()
    if not os.path.isabs(libc):  # gcc echoes the bare name when it has no such file
        return f"arm-none-eabi-gcc has no C library (newlib) {install}"
    return None


def _run(cmd: list[str], timeout: float = 60.0, **kw) -> subprocess.CompletedProcess:
    proc = subprocess.run(
        cmd,
        capture_output=True,
        text=True,
        check=False,
        timeout=timeout,
        stdin=subprocess.DEVNULL,
        **kw,
    )
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)}\nexit {proc.returncode}\n{proc.stdout}{proc.stderr}")
    return proc


def export_float(
    preset: str, ts: float, out: Path, warnings: list[str] | None = None
) -> list[Path]:
    """``aiofl export PRESET --ts TS --precision float --out OUT`` (in-process); the C
    sources it wrote (every ``*.c``: the controller, and a parameter instance if separate).
    Its warnings are appended to ``warnings``."""
    from typer.testing import CliRunner

    from aiofl.cli.app import app

    res = CliRunner().invoke(
        app, ["export", preset, "--ts", repr(ts), "--precision", "float", "--out", str(out)]
    )
    if res.exit_code != 0:
        raise RuntimeError(f"aiofl export {preset} failed ({res.exit_code}):\n{res.output}")
    if warnings is not None:
        warnings += [ln for ln in res.output.splitlines() if "warning" in ln]
    return sorted(p for p in out.glob("*.c") if p.name not in OWN_SOURCES)


@dataclass
class ControllerBuild:
    """The controller's objects for one target and what they cost."""

    target: Target
    objects: list[Path]
    text: int  # bytes of code and read-only data (arm-none-eabi-size: text), all objects
    data: int
    bss: int
    stack: dict[str, tuple[int, str]] = field(default_factory=dict)  # function: (bytes, kind)
    undefined: list[str] = field(default_factory=list)  # symbols the objects call
    call_sites: dict[str, int] = field(default_factory=dict)  # calls of each in the code
    params_text: int = 0  # of ``text``: the parameter instance's object (``*_params.c``)

    def double_calls(self) -> list[str]:
        """The double-precision run-time calls (``__aeabi_d*``, ``__aeabi_*2d``)."""
        return [s for s in self.undefined if re.match(r"__aeabi_(d\w+|\w+2d)$", s)]

    def float_calls(self) -> list[str]:
        """The soft-float single-precision calls (``__aeabi_f*``, ``__aeabi_*2f``)."""
        double = self.double_calls()  # __aeabi_f2d is one of those
        return [
            s
            for s in self.undefined
            if re.match(r"__aeabi_(f\w+|u?[il]2f)$", s) and s not in double
        ]


def signal_is_double(sources: list[Path]) -> bool:
    """Whether the export takes y and r as double by default in its float build (the params
    API's ``NAME_signal``; ``-DNAME_SIGNAL_IS_FLOAT`` makes them float)."""
    return any("_SIGNAL_IS_FLOAT" in p.read_text() for p in sources[0].parent.glob("*.h"))


def compile_controller(
    sources: list[Path], target: Target, out: Path, defines: dict[str, str] | None = None
) -> ControllerBuild:
    """Each source to an object, ``-Os -fstack-usage``, with the target's flags."""
    out.mkdir(parents=True, exist_ok=True)
    objs, stack = [], {}
    defs = [f"-D{k}={v}" for k, v in (defines or {}).items()]
    for src in sources:
        obj = out / (src.stem + ".o")
        flags = [*COMMON, "-Os", *target.cpu_flags, *defs, "-ffunction-sections", "-fdata-sections"]
        _run(
            [
                "arm-none-eabi-gcc",
                *flags,
                "-fstack-usage",
                f"-I{src.parent}",
                "-c",
                str(src),
                "-o",
                str(obj),
            ]
        )
        objs.append(obj)
        for line in obj.with_suffix(".su").read_text().splitlines():
            where, size, kind = line.rsplit("\t", 2)
            stack[where.rsplit(":", 1)[-1]] = (int(size), kind)
    sizes = _run(["arm-none-eabi-size", *map(str, objs)]).stdout.splitlines()[1:]
    text, data, bss = (sum(int(row.split()[i]) for row in sizes) for i in range(3))
    params = sum(int(row.split()[0]) for row in sizes if row.split()[-1].endswith("_params.o"))
    nm = _run(["arm-none-eabi-nm", "-u", *map(str, objs)]).stdout
    undefined = sorted({ln.split()[-1] for ln in nm.splitlines() if ln.strip().startswith("U")})
    relocs = _run(["arm-none-eabi-objdump", "-dr", *map(str, objs)]).stdout
    sites = {
        name: len(re.findall(rf"R_ARM_\w+\s+{name}$", relocs, flags=re.M)) for name in undefined
    }
    return ControllerBuild(target, objs, text, data, bss, stack, undefined, sites, params)


def link_firmware(
    ctrl: ControllerBuild,
    include: Path,
    out: Path,
    defines: dict[str, str] | None = None,
    name: str = "loop",
    shared_math: bool = False,
) -> Path:
    """The closed-loop firmware (``loop.c``, ``startup.c`` and the controller's objects;
    ``include``: the export's directory, for its header).  ``shared_math``: the libm
    functions of ``mathf.c`` (as the host build's) instead of newlib's."""
    defs = [f"-D{k}={v}" for k, v in (defines or {}).items()]
    elf = out / f"{name}-{ctrl.target.board}.elf"
    cmd = [
        "arm-none-eabi-gcc",
        *COMMON,
        "-O2",
        *ctrl.target.cpu_flags,
        *defs,
        f"-I{FIRMWARE}",
        f"-I{include}",
        "-nostartfiles",
        f"-T{FIRMWARE / 'cortex_m.ld'}",
        "-Wl,--gc-sections",
        "-o",
        str(elf),
        str(FIRMWARE / "loop.c"),
        str(FIRMWARE / "startup.c"),
        *([str(FIRMWARE / "mathf.c")] if shared_math else []),
        *map(str, ctrl.objects),
        "-lm",
    ]
    _run(cmd)
    return elf


def build_host(
    sources: list[Path],
    out: Path,
    defines: dict[str, str] | None = None,
    shared_math: bool = False,
) -> Path:
    """The same closed loop for the host: ``cc -std=c99 -O2 -ffp-contract=off -DHOST``
    (``shared_math``: with ``mathf.c``'s libm functions instead of glibc's)."""
    exe = out / ("loop-host-shared-math" if shared_math else "loop-host")
    inc = sources[0].parent
    defs = [f"-D{k}={v}" for k, v in (defines or {}).items()]
    cmd = ["cc", *COMMON, "-O2", "-DHOST", *defs, f"-I{inc}", "-o", str(exe)]
    own = [FIRMWARE / "loop.c", *([FIRMWARE / "mathf.c"] if shared_math else [])]
    _run([*cmd, *map(str, own), *map(str, sources), "-lm"])
    return exe


def _c_float(y: float) -> str:
    if math.isnan(y):
        return '__builtin_nanf("")'
    if math.isinf(y):
        return ("-" if y < 0 else "") + "__builtin_inff()"
    return f"{y.hex()}f"


def write_replay(
    sources: list[Path], out: Path, steps: int, defines: dict[str, str] | None = None
) -> int | None:
    """Record y(t_k), k < ``steps``, of the host's closed loop (-DRECORD; the same bits as
    on the targets, tests/test_cortex_m.py) as ``replay.h`` in the export's directory, for a
    -DREPLAY firmware: the controller's calls of the closed loop without the plant.  The
    first sample whose y is not finite (the float loop diverged), or None."""
    record = {**(defines or {}), "RECORD": "1", "N_STEPS": str(steps)}
    values = run_host(build_host(sources, out, record))
    ys = [values[f"y_{k}"] for k in range(steps)]
    body = ",\n".join(f"    {_c_float(y)}" for y in ys)
    text = (
        "/* y(t_k) of a recorded closed loop (loop.c -DRECORD) */\n"
        f"static const float Y_REC[{steps}] = {{\n{body}\n}};\n"
    )
    (sources[0].parent / "replay.h").write_text(text)
    return next((k for k, y in enumerate(ys) if not math.isfinite(y)), None)


def parse(text: str) -> dict[str, float]:
    """The ``name 0x<bits>`` lines: each value exactly, as a Python float."""
    values = {}
    for name, bits in re.findall(r"^(\w+) 0x([0-9a-f]{8})$", text, flags=re.M):
        values[name] = struct.unpack(">f", bytes.fromhex(bits))[0]
    if "done" not in text.split():
        raise RuntimeError(f"the program did not finish:\n{text}")
    return values


def qemu_command(elf: Path, board: str, *extra: str) -> list[str]:
    return [
        "qemu-system-arm",
        "-M",
        board,
        "-nographic",
        "-monitor",
        "none",
        "-semihosting-config",
        "enable=on,target=native",
        *extra,
        "-kernel",
        str(elf),
    ]


def run_qemu(elf: Path, board: str, *extra: str, timeout: float = 30.0) -> dict[str, float]:
    """Run the firmware to its semihosting exit; its output lines (qemu writes semihosting
    console output to its standard error)."""
    proc = _run(qemu_command(elf, board, *extra), timeout=timeout)
    return parse(proc.stdout + proc.stderr)


def run_host(exe: Path) -> dict[str, float]:
    return parse(_run([str(exe)]).stdout)


def icount_instructions(values: dict[str, float]) -> float:
    """Instructions per step beyond the empty loop, from a ``-icount shift=0`` run on the
    AN386: (ticks_step - ticks_base) * 40 / N_COUNT."""
    return (values["ticks_step"] - values["ticks_base"]) * SYSTICK_INSNS / values["n_count"]


def _singlestep_flag() -> list[str]:
    helptext = _run(["qemu-system-arm", "-help"]).stdout
    if re.search(r"^-singlestep", helptext, flags=re.M):
        return ["-singlestep"]  # qemu < 8.1
    return ["-accel", "tcg,one-insn-per-tb=on"]


def traced_instructions(
    elf: Path, board: str, functions: tuple[str, ...], out: Path
) -> dict[str, list[int]]:
    """The exact instruction count of every call of each of ``functions``: qemu traces each
    executed instruction (one per translation block, no chaining); a call runs from the
    function's entry to the return address after a ``bl`` to it (callees included)."""
    nm = _run(["arm-none-eabi-nm", str(elf)]).stdout
    entry = {}
    for line in nm.splitlines():
        addr, _, name = line.split()[-3:] if len(line.split()) == 3 else ("", "", "")
        if name in functions:
            entry[int(addr, 16) & ~1] = name
    dis = _run(["arm-none-eabi-objdump", "-d", str(elf)]).stdout
    returns: set[int] = set()
    for addr, name in re.findall(r"^\s*([0-9a-f]+):\s.*\bbl\s+[0-9a-f]+ <(\w+)>", dis, flags=re.M):
        if name in functions:
            returns.add(int(addr, 16) + 4)
    log = out / f"trace-{board}.log"
    cmd = qemu_command(elf, board, *_singlestep_flag(), "-d", "exec,nochain", "-D", str(log))
    _run(cmd, timeout=120)
    counts: dict[str, list[int]] = {name: [] for name in functions}
    current, n = None, 0
    pcs = re.compile(r"^Trace \d+: \S+ \[[0-9a-f]+/([0-9a-f]+)/", flags=re.M)
    with log.open() as fh:
        for line in fh:
            m = pcs.match(line)
            if m is None:
                continue
            pc = int(m.group(1), 16)
            if current is None:
                if pc in entry:
                    current, n = entry[pc], 1
            elif pc in returns:
                counts[current].append(n)
                current = None
            else:
                n += 1
    os.unlink(log)
    return counts
