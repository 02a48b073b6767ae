"""
An open-loop unstable plant: the maglev
=======================================

A ball levitated under an electromagnet (``tests/data/maglev.toml``): relative degree 3,
open-loop unstable at its operating point, and β < 0 there, so b0 is negative.  The first
LADRC of ``tests/data/maglev-ladrc.toml`` holds it at 1 cm and steps it by 1 mm; started
at u = 0 the ball drops before the observer catches up, started at the operating point
(``[controller.eso] u0 = "trim"``, ``tests/data/maglev-ladrc-trim.toml``) it does not.
On the command line::

    aiofl trim tests/data/maglev-ladrc.toml
    aiofl simulate tests/data/maglev-ladrc-trim.toml --out runs/maglev
    aiofl simulate tests/data/maglev-ladrc-trim.toml --ts 1e-3 --out runs/maglev-1ms
"""

from pathlib import Path

import matplotlib.pyplot as plt

from aiofl import load_config
from aiofl.plants.operating_point import trim

try:
    DATA = Path(__file__).resolve().parents[1] / "tests" / "data"
except NameError:  # sphinx-gallery runs the example in its folder, without __file__
    DATA = Path.cwd().resolve().parent / "tests" / "data"

# %%
# The operating point
# -------------------
# z = 1 cm needs a coil current of about 0.7 A; one pole is in the right half plane.
zero_start = load_config(str(DATA / "maglev-ladrc.toml"))
trim_start = load_config(str(DATA / "maglev-ladrc-trim.toml"))
point = trim(zero_start.plant, 0.01, x_guess=zero_start.scenario.x0)
print(point.text("m", "V"))

# %%
# Two starts, continuous and sampled
# ----------------------------------
runs = {
    "u0 = 0": zero_start.simulate(),
    'u0 = "trim"': trim_start.simulate(),
    'u0 = "trim", Ts = 1 ms': trim_start.with_sample_time(1e-3).simulate(),
}
for label, res in runs.items():
    before = res["y"][res.t < 0.2] - 0.01
    print(
        f"{label:>22}: {res.status}, before the step z - 1 cm within "
        f"[{1e3 * before.min():.3g}, {1e3 * before.max():.3g}] mm, ITAE {res.metrics['itae']:.3g}"
    )

fig, (ax_y, ax_u) = plt.subplots(2, 1, sharex=True, figsize=(7, 5))
for label, res in runs.items():
    ax_y.plot(res.t, 1e3 * res["y"], label=label)
    ax_u.plot(res.t, res["u"], label=label)
ax_y.plot(res.t, 1e3 * res["r"], "k--", lw=0.8, label="r")
ax_y.set_ylabel("z [mm] (down is away from the magnet)")
ax_u.set_ylabel("u [V]")
ax_u.set_xlabel("t [s]")
ax_y.legend(fontsize=8)
fig.tight_layout()
