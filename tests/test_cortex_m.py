"""The exported float controller on microcontrollers (issue 23, proof on a Cortex-M).

frontier-s1-ladrc exported at Ts = 1 ms in float (``aiofl export --precision float``) is
cross-compiled for a Cortex-M4F (``-mcpu=cortex-m4 -mthumb -mfpu=fpv4-sp-d16
-mfloat-abi=hard -Os``) and a Cortex-M0+ (``-mcpu=cortex-m0plus -mthumb -Os``): its code size
(arm-none-eabi-size), stack per call (``-fstack-usage``) and run-time calls (arm-none-eabi-nm)
are reported and checked (when the export takes y and r as double in a float build, the
soft-float double calls that costs are reported, and a build with
``-DAIOFL_SIGNAL_IS_FLOAT`` has none).  The closed loop of ``tests/firmware/loop.c`` (the
controller and the SLFJM stepped by RK4 in float, 5 s at 1 ms) runs on qemu's MPS2 AN386
(Cortex-M4 with FPU) and on its micro:bit (Cortex-M0, the M0+ build) with semihosting
output, and gives the host float build's ITAE and commands bit for bit (a design whose C
calls libm, with one implementation of expf, logf... linked on both sides).  qemu counts
instructions, not cycles: the step's count from SysTick under ``-icount shift=0`` equals the
count from an instruction trace.  Helpers: ``tests/cortex_m.py``; figures:
``benchmarks/bench_mcu.py``.

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
    signal_is_double,
    traced_instructions,
    write_replay,
)

REASON = missing_tools()
pytestmark = pytest.mark.skipif(REASON is not None, reason=f"Cortex-M tests: {REASON}")

PRESET = "frontier-s1-ladrc"
TS = 1e-3
N_COUNT = 500  # controller steps of the SysTick-timed run


@pytest.fixture(scope="module")
def build(tmp_path_factory):
    """One export, its objects for both targets (and, when the export takes double
    signals, for float signals too), the firmware and the host program, and their outputs
    (qemu on the AN386 with -icount shift=0, on the micro:bit without)."""
    tmp = tmp_path_factory.mktemp("cortex-m")
    sources = export_float(PRESET, TS, tmp / "export")
    ctrl = {t: compile_controller(sources, t, tmp / t.board) for t in (M4F, M0P)}
    float_signal = {}
    if signal_is_double(sources):
        for t in (M4F, M0P):
            out = tmp / f"{t.board}-float-signal"
            float_signal[t] = compile_controller(sources, t, out, {"AIOFL_SIGNAL_IS_FLOAT": "1"})
    include = sources[0].parent
    elf = {t: link_firmware(ctrl[t], include, tmp / t.board) for t in (M4F, M0P)}
    host = run_host(build_host(sources, tmp))
    target = {M4F: run_qemu(elf[M4F], M4F.board), M0P: run_qemu(elf[M0P], M0P.board)}
    return {
        "tmp": tmp,
        "sources": sources,
        "ctrl": ctrl,
        "float_signal": float_signal,
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


def test_a_design_calling_libm_equals_the_host_with_the_same_math(tmp_path):
    """retuned-s1-leso's C calls expf, logf and sqrtf (fal): with newlib's on the target and
    glibc's on the host the loops part by the libraries' last bits (reported); linked with
    one implementation on both sides (tests/firmware/mathf.c) they are equal bit for bit."""
    sources = export_float("retuned-s1-leso", TS, tmp_path / "export")
    ctrl = compile_controller(sources, M4F, tmp_path / "m4f")
    assert {"expf", "logf"} <= set(ctrl.undefined)
    include = sources[0].parent
    runs = {}
    for shared in (False, True):
        name = "shared" if shared else "own"
        elf = link_firmware(ctrl, include, tmp_path, name=name, shared_math=shared)
        host = run_host(build_host(sources, tmp_path, shared_math=shared))
        runs[shared] = (host, run_qemu(elf, M4F.board))
    host, target = runs[False]
    print(
        "retuned-s1-leso, newlib on the M4F vs glibc on the host: ITAE relative difference "
        f"{abs(target['itae'] - host['itae']) / host['itae']:.2e}"
    )
    host, target = runs[True]
    assert 0.0 < host["itae"] < 1.0
    assert all(target[k] == v for k, v in host.items()), (host, target)


def _report(ctrl) -> str:
    calls = {n: ctrl.call_sites.get(n, 0) for n in ctrl.undefined}
    return (
        f"{PRESET} float, {ctrl.target.name}: text {ctrl.text} B (parameter instance "
        f"{ctrl.params_text} B), data {ctrl.data} B, "
        f"bss {ctrl.bss} B; stack {ctrl.stack}; calls (call sites) {calls}"
    )


def test_controller_size_stack_and_runtime_calls(build):
    """Code size and stack per call of the controller object.  On the M0+ (no FPU) the
    float arithmetic calls libgcc's __aeabi_f* routines, on the M4F none.  Double-precision
    run-time calls (__aeabi_d*): none when y and r are float at the API; when the export
    takes them as double (its default in a float build) the calls are reported, and the
    build with -DAIOFL_SIGNAL_IS_FLOAT has none."""
    m4, m0 = build["ctrl"][M4F], build["ctrl"][M0P]
    for ctrl in (m4, m0, *build["float_signal"].values()):
        print(_report(ctrl))
        assert 0 < ctrl.text < 2048 and ctrl.data == 0 and ctrl.bss == 0
        step = next(v for k, v in ctrl.stack.items() if k.endswith("_step"))
        assert step[1] == "static" and step[0] <= 128, ctrl.stack  # bounded, no VLA / alloca
        assert all(kind == "static" for _, kind in ctrl.stack.values())
    assert m4.float_calls() == []
    assert {"__aeabi_fadd", "__aeabi_fmul"} <= set(m0.float_calls())
    if build["float_signal"]:
        for ctrl in build["float_signal"].values():
            assert ctrl.double_calls() == [], ctrl.undefined
        assert build["float_signal"][M4F].float_calls() == []
        print(
            "M4F double calls with double signals:",
            {n: m4.call_sites[n] for n in m4.double_calls()},
        )
    else:
        assert m4.double_calls() == [] and m0.double_calls() == []


def test_instructions_per_step_icount_equals_the_trace(build):
    """qemu has no cycle model of the M4 (and DWT CYCCNT is not modelled); it counts
    instructions.  Under -icount shift=0 (1 ns per instruction) the AN386's 25 MHz SysTick
    ticks every 40 instructions: SysTick around 500 steps and around the same loop with a
    trivial function gives the step's instructions beyond the trivial call; an instruction
    trace (-singlestep -d exec,nochain) of the same firmware counts each call exactly.  They
    agree to the tick's resolution (40 / 500 per step, twice).  The firmware replays the
    closed loop's first 200 samples (loop.c -DREPLAY, the recorded y, no plant): its
    commands are the closed loop's, bit for bit."""
    steps = 200
    write_replay(build["sources"], build["tmp"], steps)
    defines = {"REPLAY": "1", "N_STEPS": str(steps), "N_COUNT": str(N_COUNT)}
    include = build["sources"][0].parent
    elf = link_firmware(build["ctrl"][M4F], include, build["tmp"], defines, name="replay")
    replayed = run_qemu(elf, M4F.board, "-icount", "shift=0")
    for key in ("u_0", "u_1", "u_2", "u_10", "u_100"):
        assert replayed[key] == build["target"][M4F][key], key
    counts = traced_instructions(elf, M4F.board, ("aiofl_step", "trivial"), build["tmp"])
    step, trivial = counts["aiofl_step"], counts["trivial"]
    assert len(step) == steps + N_COUNT and len(trivial) == N_COUNT and len(set(trivial)) == 1
    closed, timed = step[:steps], step[steps:]
    by_trace = sum(timed) / N_COUNT - trivial[0]
    by_icount = icount_instructions(replayed)
    print(
        f"M4F instructions per aiofl_step: closed loop {min(closed)}..{max(closed)} "
        f"(trace), timed run {sum(timed) / N_COUNT:.2f} (trace) = {by_icount:.2f} (icount) "
        f"+ {trivial[0]} (trivial call)"
    )
    assert abs(by_icount - by_trace) <= 2 * 40 / N_COUNT
    assert 50 < min(closed) <= max(closed) < 2000
