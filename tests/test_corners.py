"""The worst cases of the uncertainty box (issue 21): corners, local search, β/b0 range.

The reference loop: LADRC (ρ = 2, linear ESO with poles at -ω0, linear SEF with poles at
-ωc, exact reference derivatives) on the pendulum :math:`\\ddot\\theta = -(g/l)\\sin\\theta
- c/(ml^2)\\dot\\theta + u/(ml^2)`, tracking a 0.05-rad sine (so :math:`\\sin\\theta
\\approx \\theta`).  Linearised, plant + observer + feedback are a 5-state LTI system
whose matrix depends on the gain ratio :math:`k = \\beta/b_0` (and slightly on the plant's
own terms); its eigenvalues give the stability interval in closed form (bisection of the
largest real part, numpy), against which the engine's corners and β/b0 bisection are
checked.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from aiofl.analysis.corners import beta_ranges, beta_scaling, run_box_robustness
from aiofl.cli.app import app
from aiofl.config import load_config
from aiofl.uncertainty import (
    MAX_FULL_FACTORIAL,
    UncertaintyModel,
    box_draws,
    corner_design,
    corner_draws,
)

W0, WC = 500.0, 100.0  # fast loop: beyond the bound the oscillation grows within a second
G_L, C_ML2, BETA = 9.81 / 0.5, 0.1 / 0.25, 1.0 / 0.25  # the pendulum's nominal terms

RUN = """
name = "pend-ladrc"
plant = "pendulum"
[scenario]
t_final = {t_final}
[scenario.reference]
kind = "sine"
amplitude = 0.05
omega = 1.0
[controller]
structure = "LADRC"
td_kind = "exact"
rho = 2
n_feedback = 2
[controller.eso]
omega0 = {w0}
[controller.sef]
omega_c = {wc}
[controller.law]
b0 = {b0}
[simulation]
dt = 1e-4
divergence_threshold = 1e4
[uncertainty]
draws = 6
seed = 3
[uncertainty.parameters]
m = {{ uniform = 0.5 }}
c = {{ uniform = 0.5 }}
"""


def _config(tmp_path: Path, b0: float, t_final: float = 3.0) -> Path:
    path = tmp_path / "pend.toml"
    path.write_text(RUN.format(t_final=t_final, w0=W0, wc=WC, b0=b0))
    return path


def _closed_loop(k: float, c_ml2: float = C_ML2) -> np.ndarray:
    """States (θ, θ', z1, z2, z3), r = 0; u = -(ωc² z1 + 2ωc z2 + z3)/b0 and β = k b0."""
    ll = np.array([3 * W0, 3 * W0**2, W0**3])
    kk = np.array([WC**2, 2 * WC, 1.0])
    a = np.zeros((5, 5))
    a[0, 1] = 1.0
    a[1, 0], a[1, 1] = -G_L, -c_ml2
    a[1, 2:] = -k * kk  # β u = -k (kk · z)
    a[2:, 0] += ll  # observer: z' = A z + B b0 u + L (θ - z1)
    a[2:, 2] -= ll
    a[2, 3] = a[3, 4] = 1.0
    a[3, 2:] -= kk  # b0 u = -(kk · z)
    return a


def _stable(k: float, c_ml2: float = C_ML2) -> bool:
    return bool(np.linalg.eigvals(_closed_loop(k, c_ml2)).real.max() < 0)


def _bound(stable_k: float, unstable_k: float) -> float:
    """The stability boundary between a stable and an unstable k (bisection in ln k)."""
    a, b = stable_k, unstable_k
    for _ in range(60):
        m = float(np.sqrt(a * b))
        a, b = (m, b) if _stable(m) else (a, m)
    return a


# ----------------------------------------------------------------------- corner designs
def test_corner_draws_are_the_2k_distinct_corners_of_the_box() -> None:
    spec = UncertaintyModel(
        parameters={
            "J_l": {"uniform": 0.2},
            "K_s": {"log_uniform": [0.5, 2.0]},
            "R_m": {"normal": 0.1},
        },
        ts=[5e-4, 2e-3],
    )
    d, text = corner_draws(spec, dt=1e-4)
    cols = d.columns()
    edges = {"J_l": (0.8, 1.2), "K_s": (0.5, 2.0), "R_m": (0.7, 1.3), "ts": (5e-4, 2e-3)}
    assert list(cols) == list(edges) and len(d) == 2**4 and "2^4 = 16" in text
    pts = np.column_stack([cols[n] for n in edges])
    for j, (lo, hi) in enumerate(edges.values()):  # every value at an edge, both edges used
        assert np.all(np.isclose(pts[:, j], lo) | np.isclose(pts[:, j], hi))
        assert np.isclose(pts[:, j], lo).sum() == np.isclose(pts[:, j], hi).sum() == 8
    assert len({tuple(np.round(p, 12)) for p in pts}) == 16  # distinct
    # deterministic (noise seeds too), and box_draws maps unit corners onto the same plants
    again, _ = corner_draws(spec, dt=1e-4)
    for n in edges:
        np.testing.assert_array_equal(cols[n], again.columns()[n])
    np.testing.assert_array_equal(d.noise_seeds, again.noise_seeds)
    signs, _ = corner_design(4)
    via_box = box_draws(spec, (signs + 1) / 2, dt=1e-4).columns()
    for n in edges:
        np.testing.assert_allclose(via_box[n], cols[n], rtol=1e-12)


def test_beyond_twelve_dimensions_a_resolution_iv_fraction() -> None:
    table, text = corner_design(MAX_FULL_FACTORIAL + 2)
    assert table.shape == (2**12, 14) and "resolution IV" in text
    assert len({tuple(r) for r in table}) == 2**12  # distinct corners
    assert np.all(table.sum(axis=0) == 0)  # balanced: every factor at each edge half the time
    x = table.astype(np.int64)
    inter = [x[:, i] * x[:, j] for i in range(14) for j in range(i + 1, 14)]
    gram = x.T @ np.column_stack([x, *inter])  # main effects against mains and interactions
    gram[np.arange(14), np.arange(14)] = 0  # (each main effect with itself)
    assert not gram.any()  # none aliased with another main effect or a 2-factor interaction


# ------------------------------------------------------------------------- β/b0 range
def test_beta_scaling_keeps_the_drift_and_scales_the_input_field() -> None:
    assert beta_scaling(load_config("frontier-s1-leso").plant) == {"K_m": -1.0, "R_m": -2.0}


def test_beta_range_brackets_the_eigenvalue_bound(tmp_path: Path) -> None:
    cfg = load_config(str(_config(tmp_path, b0=BETA)))  # nominal β/b0 = 1
    (r,), calls = beta_ranges([cfg])
    assert r.scaling == {"m": -1.0, "c": -1.0} and r.ratio == pytest.approx(1.0)
    assert calls == 1 + 5  # the grid, then five bisection steps (both sides together)
    hi = _bound(1.0, 20.0)
    lo = _bound(1.0, 0.05)
    # the engine sees divergence within the horizon: at most the grid's resolution below
    # the bound, a few per cent above (a slowly growing oscillation needs time)
    assert hi / 1.02 <= r.s_high <= hi * 1.05, (r.s_high, hi)
    assert lo * 0.75 <= r.s_low <= lo * 1.02, (r.s_low, lo)
    rec = r.to_dict()
    assert rec["beta_over_b0"] == pytest.approx([r.s_low, r.s_high])
    assert rec["capped"] == [False, False]


# ----------------------------------------------------------------- corners, worst case
def test_the_corners_that_diverge_are_the_analytic_ones(tmp_path: Path) -> None:
    """b0 = β/3: β/b0 = 3/m_f, so m × 0.5 puts it at 6, beyond the bound (≈ 5.1)."""
    cfg = load_config(str(_config(tmp_path, b0=BETA / 3)))
    res = run_box_robustness(cfg, beta=False)
    info = res.to_dict()
    c = info["corners"]
    cols = res.corners.columns()
    want = [
        not _stable(3.0 / m_f, C_ML2 * c_f / m_f)
        for m_f, c_f in zip(cols["m"], cols["c"], strict=True)
    ]
    assert want == list(np.isclose(cols["m"], 0.5))  # exactly the corners with m × 0.5
    np.testing.assert_array_equal(res.corner_failed, want)
    assert c["stable"] == 2 and c["corners_stable"] == 0.5
    assert {d["corner"] for d in c["failed"]} == set(np.flatnonzero(want))
    # the worst case is a diverged corner, and the search stops there at once
    w = info["worst_case"]
    assert w["itae"] is None and w["evaluations"] == 0 and w["point"]["m"] == 0.5
    assert w["start"].startswith("corner") and w["stopped_at"] == pytest.approx(
        min(d["t"] for d in c["failed"])
    )
    assert res.stable_fraction <= 1.0 and len(res.itae) == 6  # the draws are kept apart
    json.dumps(info, allow_nan=False)


def test_worst_case_search_is_bounded_seeded_and_no_better_than_its_start(
    tmp_path: Path,
) -> None:
    cfg = load_config(str(_config(tmp_path, b0=BETA, t_final=1.0)))  # every corner stable
    a = run_box_robustness(cfg, draws=2, beta=False).to_dict()
    b = run_box_robustness(cfg, draws=2, beta=False).to_dict()
    assert a["corners"]["corners_stable"] == 1.0
    wa, wb = a["worst_case"], b["worst_case"]
    assert wa == wb  # deterministic
    assert 1 <= wa["evaluations"] <= 12 and wa["itae"] >= wa["start_itae"]
    assert all(0.5 - 1e-12 <= v <= 1.5 + 1e-12 for v in wa["point"].values())


# ------------------------------------------------------------------------------ the CLI
def test_cli_prints_and_writes_the_corners(tmp_path: Path) -> None:
    cfg = _config(tmp_path, b0=BETA / 3, t_final=1.0)
    out = tmp_path / "out"
    result = CliRunner().invoke(app, ["robustness", str(cfg), "--draws", "3", "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert "corners_stable 0.5 (2 of 4" in result.output
    assert "beta/b0 stability range" in result.output and "worst case" in result.output
    info = json.loads((out / "robustness.json").read_text())
    assert info["corners"]["count"] == 4 and info["beta_range"]["scaling"] == "m x s^-1 c x s^-1"
    plain = tmp_path / "plain"
    result = CliRunner().invoke(
        app, ["robustness", str(cfg), "--draws", "3", "--no-corners", "--out", str(plain)]
    )
    assert result.exit_code == 0 and "corners_stable" not in result.output


def test_robust_tuning_draws_can_include_the_corners() -> None:
    from aiofl.tuning.prepared import draw_fields
    from aiofl.tuning.space import parse_tune_settings

    cfg = load_config("frontier-s1-leso")
    plain = draw_fields(cfg, 3, cfg.dt)
    both = draw_fields(cfg, 3, cfg.dt, corners=True)
    assert both[:3] == plain and len(both) == 3 + 16
    corners = {tuple(sorted(d["plant_scale"].items())) for d in both[3:]}
    assert len(corners) == 16
    assert all(v in (0.8, 1.2) for d in both[3:] for v in d["plant_scale"].values())
    st = parse_tune_settings({**cfg.raw["tune"]})
    assert st.robust is not None and st.robust.corners is False  # shipped tables unchanged
    st = parse_tune_settings({**cfg.raw["tune"], "robust": {"draws": 4, "corners": True}})
    assert st.robust is not None and st.robust.corners is True
