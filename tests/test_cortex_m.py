"""The exported float controller on microcontrollers (issue 23, proof on a Cortex-M).

frontier-s1-ladrc exported at Ts = 1 ms in float (``aiofl export --precision float``) is
cross-compiled for a Cortex-M4F (``-mcpu=cortex-m4 -mthumb -mfpu=fpv4-sp-d16
-mfloat-abi=hard -Os``) and a Cortex-M0+ (``-mcpu=cortex-m0plus -mthumb -Os``): its code size
(arm-none-eabi-size), stack per call (``-fstack-usage``) and run-time calls (arm-none-eabi-nm)
are reported and checked.  The closed loop of ``tests/firmware/loop.c`` (the controller and
the SLFJM stepped by RK4 in float, 5 s at 1 ms) runs on qemu's MPS2 AN386 (Cortex-M4 with
FPU) and on its micro:bit (Cortex-M0, the M0+ build) with semihosting output, and gives the
host float build's ITAE and commands bit for bit.  qemu counts instructions (not cycles):
the step's count from SysTick under ``-icount shift=0`` equals the count from an
instruction trace.  Helpers: ``tests/cortex_m.py``; figures: ``benchmarks/bench_mcu.py``.

Skipped, with the reason, when the cross toolchain or qemu is missing (``.ci/run`` installs
them on Debian)."""

from __future__ import annotations

import math

import pytest

from cortex_m import (
    M0P,
    M4F,
    build_host,
    compile_controller,
    export_float,
    icount_instructions,
    link_firmware,
    missing_tools,
    run_host,
    run_qemu,
    traced_instructions,
    write_replay,
)

REASON = missing_tools()
pytestmark = pytest.mark.skipif(REASON is not None, reason=f"Cortex-M tests: {REASON}")

PRESET = "frontier-s1-ladrc"
TS = 1e-3
N_COUNT = 2000  # controller steps of the SysTick-timed run


@pytest.fixture(scope="module")
def build(tmp_path_factory):
    """One export, its objects for both targets, the firmware and the host program, and
    their outputs (qemu on the AN386 with -icount shift=0, on the micro:bit without)."""
    tmp = tmp_path_factory.mktemp("cortex-m")
    sources = export_float(PRESET, TS, tmp / "export")
    ctrl = {t: compile_controller(sources, t, tmp / t.board) for t in (M4F, M0P)}
    elf = {
        t: link_firmware(ctrl[t], sources[0].parent, tmp / t.board, {"N_COUNT": str(N_COUNT)})
        for t in (M4F, M0P)
    }
    host = run_host(build_host(sources, tmp))
    target = {
        M4F: run_qemu(elf[M4F], M4F.board, "-icount", "shift=0"),
        M0P: run_qemu(elf[M0P], M0P.board),
    }
    return {
        "tmp": tmp,
        "sources": sources,
        "ctrl": ctrl,
        "elf": elf,
        "host": host,
        "target": target,
    }


def test_qemu_closed_loop_itae_equals_the_host_float_build(build):
    """ITAE (and ISU, y(5 s), the commands at k = 0, 1, 2, 10, 100, 1000, 4999) on the
    emulated Cortex-M4F and Cortex-M0 equal the host's (cc, float): bit for bit here, and the
    issue asks 1e-6 relative."""
    host = build["host"]
    assert 0.0 < host["itae"] < 0.01 and abs(host["y_end"]) < 1.0, host  # a working loop
    u_keys = [k for k in host if k.startswith("u_")]
    assert len(u_keys) == 7 and all(math.isfinite(host[k]) for k in u_keys)
    for target in (M4F, M0P):
        got = build["target"][target]
        assert abs(got["itae"] - host["itae"]) <= 1e-6 * abs(host["itae"]), (target.name, got)
        for key in ("itae", "isu", "y_end", *u_keys):
            assert got[key] == host[key], (target.name, key, got[key], host[key])


def test_controller_size_stack_and_runtime_calls(build):
    """Code size and stack per call of the controller object; no double-precision run-time
    call on either target (the exported API and arithmetic are float); on the M0+ (no FPU)
    the float arithmetic calls libgcc's __aeabi_f* routines, on the M4F none."""
    m4, m0 = build["ctrl"][M4F], build["ctrl"][M0P]
    for ctrl in (m4, m0):
        print(
            f"{PRESET} float, {ctrl.target.name}: text {ctrl.text} B, data {ctrl.data} B, "
            f"bss {ctrl.bss} B; stack {ctrl.stack}; calls {ctrl.undefined}"
        )
        assert 0 < ctrl.text < 2048 and ctrl.data == 0 and ctrl.bss == 0
        step = next(v for k, v in ctrl.stack.items() if k.endswith("_step"))
        assert step[1] == "static" and step[0] <= 128, ctrl.stack  # bounded, no VLA / alloca
        assert all(kind == "static" for _, kind in ctrl.stack.values())
        assert ctrl.double_calls() == [], ctrl.undefined
    assert m4.float_calls() == []
    assert {"__aeabi_fadd", "__aeabi_fmul"} <= set(m0.float_calls())


def test_instructions_per_step_icount_equals_the_trace(build):
    """qemu has no cycle model of the M4 (and DWT CYCCNT is not modelled); it counts
    instructions.  Under -icount shift=0 (1 ns per instruction) the AN386's 25 MHz SysTick
    ticks every 40 instructions: SysTick around 2000 steps and around the same loop with a
    trivial function gives the step's instructions beyond the trivial call; an instruction
    trace (-singlestep -d exec,nochain) counts each call exactly.  They agree to the tick's
    resolution (40 / 2000 per step, twice).  The trace runs a replay of the closed loop's
    first 200 samples (loop.c -DREPLAY, the recorded y, no plant): its commands are the
    closed loop's, bit for bit."""
    steps = 200
    write_replay(build["sources"], build["tmp"], steps)
    defines = {"REPLAY": "1", "N_STEPS": str(steps), "N_COUNT": "50"}
    elf = link_firmware(
        build["ctrl"][M4F], build["sources"][0].parent, build["tmp"], defines, name="replay"
    )
    replayed = run_qemu(elf, M4F.board)
    for key in ("u_0", "u_1", "u_2", "u_10", "u_100"):
        assert replayed[key] == build["target"][M4F][key], key
    counts = traced_instructions(elf, M4F.board, ("aiofl_step", "trivial"), build["tmp"])
    step, trivial = counts["aiofl_step"], counts["trivial"]
    assert len(step) == steps + 50 and len(trivial) == 50
    assert len(set(step)) == 1 and len(set(trivial)) == 1  # a linear design: no branches
    by_icount = icount_instructions(build["target"][M4F])
    print(f"M4F instructions per aiofl_step: {step[0]} (trace), icount {by_icount} + {trivial[0]}")
    assert abs(by_icount - (step[0] - trivial[0])) <= 2 * 40 / N_COUNT
    assert 50 < step[0] < 1000
