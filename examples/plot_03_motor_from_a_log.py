"""
A motor from a log to firmware
==============================

A DC motor on the bench, position measured by a 12-bit encoder at 1 kHz, and no model
you trust.  Excite it, log it, identify what an ADRC design needs (ρ, b0, the delay),
check the first design and export it as C99.  The rig is played here by aiofl's
independent scipy simulator (:mod:`aiofl.identification.synthetic`), which shares no code
with the engine being fitted.  On the command line::

    aiofl excite --kind prbs --amplitude 1 --band 20 --duration 5 --ts 1e-3 -o u.csv
    # play u on the rig, log t, u, y
    aiofl identify log.csv -o id/
    aiofl simulate id/first.toml --out runs/first
    aiofl export id/first.toml --out c/
"""

import os
import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
from typer.testing import CliRunner

from aiofl.cli.app import app
from aiofl.config import load_config, resolve_plant
from aiofl.identification.log import Log, write_log
from aiofl.identification.synthetic import measure, simulate_log

WORK = Path(tempfile.mkdtemp())  # the bench folder: the commands run in it


def aiofl(*args: str) -> None:
    """Run one ``aiofl`` command in this process in WORK, as typing it in a shell would."""
    here = Path.cwd()
    os.chdir(WORK)
    try:
        result = CliRunner().invoke(app, list(args))
    finally:
        os.chdir(here)
    print("$ aiofl " + " ".join(args))
    print(result.output)
    assert result.exit_code == 0, result.output


# %%
# The excitation
# --------------
# A PRBS exciting 0–20 Hz, ±1 V, 5 s at the rig's 1 ms (also as a C array with --c-array).
aiofl(
    "excite",
    "--kind",
    "prbs",
    "--amplitude",
    "1",
    "--band",
    "20",
    "--duration",
    "5",
    "--ts",
    "1e-3",
    "-o",
    "u.csv",
)
t, u = np.loadtxt(WORK / "u.csv", delimiter=",", comments="#", skiprows=1, unpack=True)

# %%
# The rig (simulated)
# -------------------
# The truth the identification does not see: J θ'' = K u(t − 1 ms) − b θ', so ρ = 2 and
# β = K/J = 50 rad/(V·s²); the encoder quantises to 2π/4096 rad and adds a little noise.
(WORK / "motor.toml").write_text(
    """
name = "bench_motor"
states = ["theta", "omega"]
f = ["omega", "-b/J*omega"]
g = ["0", "K/J"]
h = "theta"
output_unit = "rad"
input_unit = "V"
[params]
J = 0.01
b = 0.05
K = 0.5
""",
    encoding="utf-8",
)
motor = resolve_plant(str(WORK / "motor.toml"))
clean = simulate_log(motor, t, u, delay=1e-3)
y = measure(clean.y, noise_std=2e-4, quantum=2 * np.pi / 4096, seed=0)
write_log(Log(clean.t, clean.u, y, source="bench"), WORK / "log.csv")

# %%
# Identify
# --------
# ρ by BIC over chains of integrators, b0 with its standard error, the delay; a first
# LADRC config on the identified chain (id/first.toml).
aiofl("identify", "log.csv", "-o", "id")

# %%
# The first design, and the C
# ---------------------------
# Simulated on the identified chain, then exported at the rig's 1 ms.
first = load_config(str(WORK / "id" / "first.toml"))
res = first.simulate()
print(f"first design on the identified chain: {res.status}, ITAE {res.metrics['itae']:.3g}")
aiofl("export", "id/first.toml", "--out", "c")
header = (WORK / "c" / "aiofl_controller.h").read_text()
keys = ("_RHO ", "_TS ", "_U_MIN ", "_U_MAX ", "_LAYOUT ")
print("\n".join(line for line in header.splitlines() if any(k in line for k in keys)))

fig, (ax_log, ax_run) = plt.subplots(2, 1, figsize=(7, 5))
ax_log.plot(t, y, lw=0.8, label="logged y [rad]")
ax_log.step(t, u, lw=0.6, where="post", label="u [V]")
ax_log.set_xlabel("t [s]")
ax_log.legend(fontsize=8)
ax_log.set_title("the log")
ax_run.plot(res.t, res["r"], "k--", lw=0.8, label="r")
ax_run.plot(res.t, res["y"], label="y, first design")
ax_run.set_xlabel("t [s]")
ax_run.legend(fontsize=8)
ax_run.set_title("the first design on the identified chain")
fig.tight_layout()
