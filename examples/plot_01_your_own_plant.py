"""
Your own plant: a plant file, a first design, a simulation
==========================================================

A damped pendulum you describe yourself, as a plant file of expressions: its structure,
the operating point that holds it at 0.5 rad, the first LADRC :mod:`aiofl.analysis.first_design`
proposes, a faster version of it, and both simulated with the ideal sensor and a 12-bit
encoder.  On the command line the same steps are::

    aiofl analyze pend.toml
    aiofl trim pend.toml --y 0.5
    aiofl design pend.toml --y 0.5 -o first.toml
    aiofl simulate first.toml --out runs/first
"""

import copy
import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import tomlkit

from aiofl.analysis.first_design import first_design
from aiofl.config import parse_config, resolve_plant
from aiofl.plants.operating_point import trim

# %%
# The plant file
# --------------
# f, g and h are expressions of the states and parameters; nothing is ``eval``-ed.
PLANT = """
name = "my_pendulum"
description = "a damped pendulum driven by a torque"
states = ["theta", "omega"]
f = ["omega", "-g/l*sin(theta) - c/(m*l**2)*omega"]
g = ["0", "1/(m*l**2)"]
h = "theta"
output_unit = "rad"
input_unit = "N·m"
state_units = ["rad", "rad/s"]

[params]
m = 1.0
l = 0.5
c = 0.1
g = 9.81
"""
folder = Path(tempfile.mkdtemp())
(folder / "pend.toml").write_text(PLANT, encoding="utf-8")
plant = resolve_plant(str(folder / "pend.toml"))
print(plant.name, "- relative degree", plant.relative_degree)

# %%
# The operating point
# -------------------
# Hold θ = 0.5 rad: the state, the holding input u_e and β there (``aiofl trim``).
point = trim(plant, 0.5)
print(point.text("rad", "N·m"))

# %%
# A first design
# --------------
# b0 = β(x_e); ω_c from the unstable poles (none here: the floor of 1 rad/s), ω0 = 4 ω_c,
# checked on a step about the operating point (``aiofl design``).
proposal = first_design("pend.toml", plant, y=0.5, base_dir=folder)
print("\n".join(proposal.notes))
print("check:", proposal.status)
print(tomlkit.dumps(proposal.config))

# %%
# Faster, and on an encoder
# -------------------------
# The pendulum is open-loop stable, so the first design is slow.  Raise ω_c to 10 rad/s
# with ω0 = 4 ω_c and the prefilter at ω_c, and measure it with a 12-bit encoder too.
faster = copy.deepcopy(proposal.config)
faster["controller"]["sef"]["omega_c"] = 10.0
faster["controller"]["eso"]["omega0"] = 40.0
faster["controller"]["td"]["omega"] = 10.0
faster["scenario"]["t_final"] = 20.0
encoder = copy.deepcopy(faster)
encoder["sensor"] = {"preset": "encoder-12bit"}
first = copy.deepcopy(proposal.config)
first["scenario"]["t_final"] = 20.0

runs = {}
for label, data in (("first design", first), ("ω_c = 10", faster), ("ω_c = 10, 12-bit", encoder)):
    res = parse_config(data, label, base_dir=folder).simulate()
    runs[label] = res
    resp = res.response
    print(
        f"{label:>18}: {res.status}, ITAE {res.metrics['itae']:.4g}, settling "
        f"{resp.get('settling_time', float('nan')):.3g} s, noise in u {resp['u_noise']:.3g} N·m"
    )

fig, (ax_y, ax_u) = plt.subplots(2, 1, sharex=True, figsize=(7, 5))
for label, res in runs.items():
    ax_y.plot(res.t, res["y"], label=label)
    ax_u.plot(res.t, res["u"], label=label)
ax_y.plot(res.t, res["r"], "k--", lw=0.8, label="r")
ax_y.set_ylabel("θ [rad]")
ax_u.set_ylabel("u [N·m]")
ax_u.set_xlabel("t [s]")
ax_y.legend(fontsize=8)
ax_y.set_xlim(9, 20)
fig.tight_layout()
