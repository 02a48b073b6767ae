r"""The compiled, batched closed-loop engine.

Plant, tracking differentiator, ESO, state error feedback, linearizing law and the
performance integrals form one ODE :math:`\dot z = F(t, z)`, integrated with fixed-step
RK4 (or forward Euler) inside one numba kernel, with no Python in the time loop.  The
kernel takes a *batch* of members (one row each of controller, plant-parameter and
scenario arrays) and runs them in parallel (``prange``); one simulation is a batch of one.

State of one member::

    z = [ x (n) | TD state (RHO_MAX) | ESO state ξ̂ (RHO_MAX+1) | ITAE IAE ISE ISU IAU ]

Component kinds come from the integer row (data), so every structure shares one compiled
kernel per plant.  A member whose state becomes non-finite or exceeds
``divergence_threshold`` stops; it is reported as diverged with the time, the others carry
on.  Trajectories are stored only when asked for, every ``decimation``-th step.

Held signals (measurement noise) take the value at the start of each step for all RK4
stages, so the integrator never straddles a noise jump inside a step.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from math import ceil
from typing import Any

import numpy as np
from numpy.typing import NDArray

from aiofl import layout as L
from aiofl.controller import Controller, ControllerBatch, controller_batch
from aiofl.metrics import OPIWeights, opi
from aiofl.plant import Plant
from aiofl.scenario import Scenario, noise_sequence

__all__ = ["BatchResult", "SimulationResult", "simulate", "simulate_batch"]

_KERNELS: dict[int, Any] = {}


def _build_kernel(plant: Plant) -> Any:
    """Compile the closed-loop kernel for one plant (memoised per plant object)."""
    import numba
    from numba import njit, prange

    from aiofl.differentiators import han_td_rhs, improved_td_rhs, linear_prefilter_rhs
    from aiofl.feedback import improved_sef, nonlinear_sef
    from aiofl.law import aiofl_law, iofl_law, saturate
    from aiofl.observers import eso_rhs

    f, g, h, bd, nf = plant.compiled
    n = plant.n_states
    rmax = L.RHO_MAX
    o_td = n
    o_eso = n + rmax
    o_met = n + 2 * rmax + 1
    nz = o_met + L.N_METRIC
    n_sig = 6  # t, r, y, y_meas, u, d
    n_cols = n_sig + n + (rmax + 1) + rmax

    @njit
    def reference(t, sc, ref_samples, derivs, nd):
        """r(t) and its derivatives 0..nd into derivs."""
        kind = int(sc[L.S_REF_KIND])
        for k in range(nd + 1):
            derivs[k] = 0.0
        if kind == L.REF_SINE:
            a = sc[L.S_REF_A]
            w = sc[L.S_REF_OMEGA]
            ph = w * t + sc[L.S_REF_PHASE]
            wk = 1.0
            for k in range(nd + 1):
                derivs[k] = a * wk * np.sin(ph + 0.5 * np.pi * k)
                wk *= w
            derivs[0] += sc[L.S_REF_OFFSET]
        elif kind == L.REF_STEP:
            derivs[0] = sc[L.S_REF_OFFSET] + (sc[L.S_REF_A] if t >= sc[L.S_REF_TSTEP] else 0.0)
        else:
            dtr = sc[L.S_REF_DT]
            ns = ref_samples.shape[0]
            s = t / dtr
            k0 = int(s)
            if k0 >= ns - 1:
                derivs[0] = ref_samples[ns - 1]
            else:
                frac = s - k0
                derivs[0] = ref_samples[k0] + frac * (ref_samples[k0 + 1] - ref_samples[k0])
                if nd >= 1:
                    derivs[1] = (ref_samples[k0 + 1] - ref_samples[k0]) / dtr

    @njit
    def closed_loop(
        t, z, dz, ints, fp, betas, lin_k, p_true, p_nom, sc, ref_samples, noise_val, sig, rd, e
    ):
        """F(t, z) of one member; writes dz and the signals (r, y, y_meas, u, d) into sig."""
        eso_kind = ints[L.I_ESO]
        td_kind = ints[L.I_TD]
        sef_kind = ints[L.I_SEF]
        law_kind = ints[L.I_LAW]
        rho = ints[L.I_RHO]
        m = ints[L.I_NFB]
        x = z[0:n]
        td = z[o_td : o_td + rmax]
        xi = z[o_eso : o_eso + rmax + 1]
        dtd = dz[o_td : o_td + rmax]
        dxi = dz[o_eso : o_eso + rmax + 1]

        # reference and the differentiator's profile r_1..r_rho, feed-forward r^(rho)
        reference(t, sc, ref_samples, rd, rho if td_kind == L.TD_EXACT else 0)
        r = rd[0]
        rff = 0.0
        for i in range(rmax):
            dtd[i] = 0.0
        if td_kind == L.TD_EXACT:
            for i in range(rho):
                td[i] = rd[i]
            rff = rd[rho]
        elif td_kind == L.TD_HAN:
            dtd[0], dtd[1] = han_td_rhs(td[0], td[1], r, fp[L.F_TD_R])
        elif td_kind == L.TD_IMPROVED:
            dtd[0], dtd[1] = improved_td_rhs(
                td[0], td[1], r, fp[L.F_TD_A], fp[L.F_TD_B], fp[L.F_TD_C], fp[L.F_TD_RHO]
            )
        else:
            rff = linear_prefilter_rhs(td, dtd, rho, r, fp[L.F_TD_OMEGA])

        # plant output and measurement
        y = h(x, p_true)
        y_meas = y + noise_val
        b0 = fp[L.F_B0]

        # state error feedback and law
        if law_kind == L.LAW_AIOFL:
            for i in range(m):
                e[i] = td[i] - xi[i]
            if sef_kind == L.SEF_NONLINEAR:
                v = nonlinear_sef(e, m, fp[L.F_SEF_K :], fp[L.F_SEF_ALPHA :], fp[L.F_SEF_DELTA :])
            elif sef_kind == L.SEF_IMPROVED:
                v = improved_sef(
                    e,
                    m,
                    fp[L.F_SEF_K :],
                    fp[L.F_SEF_KB :],
                    fp[L.F_SEF_MU :],
                    fp[L.F_SEF_ALPHA :],
                    fp[L.F_SEF_DOUT],
                )
            else:
                acc = rff
                for i in range(m):
                    acc += lin_k[i] * e[i]
                v = acc / b0
            u = aiofl_law(v, xi[rho], b0)
        else:
            nfx = nf(x, p_nom)
            acc = rff
            for i in range(m):
                acc += lin_k[i] * (td[i] - nfx[i])
            u = iofl_law(acc, nfx[rho], nfx[rho + 1])
        u = saturate(u, fp[L.F_UMAX])

        # observer (always integrated: its estimates are part of the output)
        for i in range(rmax + 1):
            dxi[i] = 0.0
        eso_rhs(
            xi,
            dxi,
            rho,
            betas,
            b0,
            y_meas,
            u,
            eso_kind == L.ESO_IMPROVED,
            fp[L.F_KA],
            fp[L.F_KB],
            fp[L.F_EA],
            fp[L.F_EB],
        )

        # plant
        d = sc[L.S_DIST_AMP] if t >= sc[L.S_DIST_TIME] else 0.0
        fx = f(x, p_true)
        gx = g(x, p_true)
        for i in range(n):
            dz[i] = fx[i] + gx[i] * u
        if d != 0.0:
            bdx = bd(x, p_true)
            for i in range(n):
                dz[i] += bdx[i] * d

        # performance integrals (eq. 22)
        err = abs(y - r)
        dz[o_met + L.M_ITAE] = t * err
        dz[o_met + L.M_IAE] = err
        dz[o_met + L.M_ISE] = err * err
        dz[o_met + L.M_ISU] = u * u
        dz[o_met + L.M_IAU] = abs(u)
        sig[0] = r
        sig[1] = y
        sig[2] = y_meas
        sig[3] = u
        sig[4] = d

    @njit(parallel=True)
    def kernel(
        ints,
        floats,
        p_before,
        p_after,
        p_nom,
        scen,
        x0,
        ref_table,
        ref_row,
        noise_table,
        noise_row,
        dt,
        n_steps,
        method,
        decimation,
        store,
        threshold,
        metrics,
        status,
        t_div,
        traj,
    ):
        n_members = ints.shape[0]
        for mi in prange(n_members):
            ip = ints[mi]
            fp = floats[mi]
            sc = scen[mi]
            rho = ip[L.I_RHO]
            ref_samples = ref_table[ref_row[mi]]
            noise = noise_table[noise_row[mi]]
            n_noise = noise.shape[0]
            betas = np.zeros(rmax + 1)
            w0 = fp[L.F_OMEGA0]
            for i in range(rho + 1):
                betas[i] = fp[L.F_ALPHA + i] * w0 ** (i + 1)
            lin_k = np.zeros(rmax)
            wc = fp[L.F_SEF_OMEGA_C]
            if ip[L.I_SEF] == L.SEF_LINEAR or ip[L.I_LAW] == L.LAW_IOFL:
                binom = 1.0
                for i in range(rho):  # k_{i+1} = C(rho, i) wc^(rho - i)
                    lin_k[i] = binom * wc ** (rho - i)
                    binom = binom * (rho - i) / (i + 1)
            else:
                for i in range(rmax):
                    lin_k[i] = fp[L.F_SEF_K + i]
            z = np.zeros(nz)
            for i in range(n):
                z[i] = x0[mi, i]
            k1 = np.zeros(nz)
            k2 = np.zeros(nz)
            k3 = np.zeros(nz)
            k4 = np.zeros(nz)
            zt = np.zeros(nz)
            sig = np.zeros(5)
            rd = np.zeros(rmax + 2)
            e = np.zeros(rmax)
            std = sc[L.S_NOISE_STD]
            hold = sc[L.S_NOISE_HOLD]
            t_change = sc[L.S_PCHANGE_TIME]
            status[mi] = L.STATUS_OK
            t_div[mi] = np.nan
            row = 0
            for k in range(n_steps + 1):
                t = k * dt
                p_true = p_after[mi] if t >= t_change else p_before[mi]
                noise_val = 0.0
                if std > 0.0:
                    idx = int(t / hold + 1e-9)
                    noise_val = std * noise[idx if idx < n_noise else n_noise - 1]
                closed_loop(
                    t,
                    z,
                    k1,
                    ip,
                    fp,
                    betas,
                    lin_k,
                    p_true,
                    p_nom[mi],
                    sc,
                    ref_samples,
                    noise_val,
                    sig,
                    rd,
                    e,
                )
                if store and k % decimation == 0:
                    tr = traj[mi, row]
                    tr[0] = t
                    for j in range(5):
                        tr[1 + j] = sig[j]
                    for j in range(n):
                        tr[n_sig + j] = z[j]
                    for j in range(rmax + 1):
                        tr[n_sig + n + j] = z[o_eso + j]
                    for j in range(rmax):
                        tr[n_sig + n + rmax + 1 + j] = z[o_td + j]
                    row += 1
                if k == n_steps:
                    break
                if method == L.METHOD_EULER:
                    for j in range(nz):
                        z[j] += dt * k1[j]
                else:
                    th = t + 0.5 * dt
                    ph = p_after[mi] if th >= t_change else p_before[mi]
                    for j in range(nz):
                        zt[j] = z[j] + 0.5 * dt * k1[j]
                    closed_loop(
                        th,
                        zt,
                        k2,
                        ip,
                        fp,
                        betas,
                        lin_k,
                        ph,
                        p_nom[mi],
                        sc,
                        ref_samples,
                        noise_val,
                        sig,
                        rd,
                        e,
                    )
                    for j in range(nz):
                        zt[j] = z[j] + 0.5 * dt * k2[j]
                    closed_loop(
                        th,
                        zt,
                        k3,
                        ip,
                        fp,
                        betas,
                        lin_k,
                        ph,
                        p_nom[mi],
                        sc,
                        ref_samples,
                        noise_val,
                        sig,
                        rd,
                        e,
                    )
                    t1 = t + dt
                    p1 = p_after[mi] if t1 >= t_change else p_before[mi]
                    for j in range(nz):
                        zt[j] = z[j] + dt * k3[j]
                    closed_loop(
                        t1,
                        zt,
                        k4,
                        ip,
                        fp,
                        betas,
                        lin_k,
                        p1,
                        p_nom[mi],
                        sc,
                        ref_samples,
                        noise_val,
                        sig,
                        rd,
                        e,
                    )
                    for j in range(nz):
                        z[j] += dt / 6.0 * (k1[j] + 2.0 * k2[j] + 2.0 * k3[j] + k4[j])
                bad = False
                for j in range(nz):
                    if not abs(z[j]) < threshold:  # also catches NaN
                        bad = True
                        break
                if bad:
                    status[mi] = L.STATUS_DIVERGED
                    t_div[mi] = (k + 1) * dt
                    break
            for j in range(L.N_METRIC):
                metrics[mi, j] = z[o_met + j]

    kernel.n_cols = n_cols  # type: ignore[attr-defined]
    _ = numba  # imported for side effects of configuration only
    return kernel


def kernel_for(plant: Plant) -> Any:
    """The compiled kernel of ``plant`` (built on first use, then reused)."""
    key = id(plant)
    if key not in _KERNELS:
        _KERNELS[key] = (plant, _build_kernel(plant))
    return _KERNELS[key][1]


# ---------------------------------------------------------------------------- results
@dataclass(frozen=True)
class SimulationResult:
    """One member's result.

    Attributes
    ----------
    metrics
        ``itae, iae, ise, isu, iau`` over the horizon (None if diverged).
    diverged, diverged_at
        Whether the member diverged, and when [s].
    t, signals
        Saved time points and a dict of signals by column name (``r, y, y_meas, u, d,
        x1.., xi_hat1.., r1..``); empty if trajectories were not stored.
    """

    metrics: dict[str, float] | None
    diverged: bool
    diverged_at: float | None
    t: NDArray[np.float64]
    signals: dict[str, NDArray[np.float64]]

    def opi(self, weights: OPIWeights | None = None) -> float | None:
        """OPI (eq. 22) of this run, or None if it diverged."""
        if self.metrics is None:
            return None
        m = self.metrics
        return float(opi(m["itae"], m["isu"], m["iau"], weights))

    def __getitem__(self, name: str) -> NDArray[np.float64]:
        return self.signals[name]


@dataclass(frozen=True)
class BatchResult:
    """Results of a batch: ``metrics`` (B, 5) by :data:`aiofl.layout.METRIC_NAMES`,
    ``diverged`` (B,), ``diverged_at`` (B,) [s, NaN if not], ``trajectories`` (B, T, C)
    or None, with ``columns`` naming C."""

    metrics: NDArray[np.float64]
    diverged: NDArray[np.bool_]
    diverged_at: NDArray[np.float64]
    trajectories: NDArray[np.float64] | None
    columns: tuple[str, ...]
    dt: float

    def __len__(self) -> int:
        return int(self.metrics.shape[0])

    def metric(self, name: str) -> NDArray[np.float64]:
        """One metric for every member (NaN where the member diverged)."""
        col = self.metrics[:, L.METRIC_NAMES.index(name)].copy()
        col[self.diverged] = np.nan
        return col

    def opi(self, weights: OPIWeights | None = None) -> NDArray[np.float64]:
        """OPI (eq. 22) of every member (NaN where the member diverged)."""
        return np.asarray(opi(self.metric("itae"), self.metric("isu"), self.metric("iau"), weights))

    def member(self, i: int) -> SimulationResult:
        """Member ``i`` as a :class:`SimulationResult` (trajectory cut at divergence)."""
        div = bool(self.diverged[i])
        mets = (
            None
            if div
            else {k: float(v) for k, v in zip(L.METRIC_NAMES, self.metrics[i], strict=True)}
        )
        t_div = float(self.diverged_at[i]) if div else None
        if self.trajectories is None:
            return SimulationResult(mets, div, t_div, np.empty(0), {})
        tr = self.trajectories[i]
        tr = tr[~np.isnan(tr[:, 0])]
        sig = {c: tr[:, j] for j, c in enumerate(self.columns) if c != "t"}
        return SimulationResult(mets, div, t_div, tr[:, 0], sig)


# ------------------------------------------------------------------------------- API
def _as_list(x: Any, n: int, what: str) -> list[Any]:
    if isinstance(x, (list, tuple)):
        if len(x) not in (1, n):
            raise ValueError(f"{len(x)} {what} for a batch of {n}")
        return list(x) * (n if len(x) == 1 else 1)
    return [x] * n


def simulate_batch(
    plant: Plant,
    controllers: Controller | Sequence[Controller] | ControllerBatch,
    scenarios: Scenario | Sequence[Scenario],
    *,
    dt: float = 1e-4,
    method: str = "rk4",
    store: bool = False,
    decimation: int = 10,
    divergence_threshold: float = 1e10,
) -> BatchResult:
    """Simulate a batch of closed loops in one compiled, parallel call.

    Parameters
    ----------
    plant
        The plant (its kernel is compiled on first use and cached).
    controllers
        One controller, a sequence (one per member) or a packed :class:`ControllerBatch`.
    scenarios
        One scenario for all members, or one per member; all share ``t_final``.
    dt
        Fixed step [s].
    method
        ``"rk4"`` or ``"euler"``.
    store, decimation
        Store trajectories, every ``decimation``-th step.
    divergence_threshold
        A member whose state leaves ``|z| < threshold`` (or becomes NaN) is stopped and
        reported as diverged.

    Returns
    -------
    BatchResult
    """
    if method not in L.METHODS:
        raise ValueError(f"method = {method!r}; allowed: {', '.join(L.METHODS)}")
    if not dt > 0:
        raise ValueError(f"dt = {dt}; allowed: > 0")
    if decimation < 1:
        raise ValueError(f"decimation = {decimation}; allowed: >= 1")
    batch = (
        controllers
        if isinstance(controllers, ControllerBatch)
        else controller_batch(
            controllers if isinstance(controllers, Controller) else list(controllers)
        )
    )
    b = len(batch)
    scens = _as_list(scenarios, b, "scenarios")
    t_final = scens[0].t_final
    if any(abs(s.t_final - t_final) > 1e-12 for s in scens):
        raise ValueError("all scenarios in one batch must share t_final")
    n_steps = round(t_final / dt)
    n = plant.n_states

    # per-scenario tables (computed once per distinct scenario)
    uniq: dict[int, int] = {}
    for s in scens:
        uniq.setdefault(id(s), len(uniq))
    distinct = list({id(s): s for s in scens}.values())
    rows = np.array([uniq[id(s)] for s in scens], dtype=np.int64)
    p_nom_vec = plant.param_vector()
    p_nom = np.repeat(p_nom_vec[None, :], b, axis=0)
    p_before_d = np.stack([p_nom_vec for _ in distinct])
    p_after_d = np.stack([plant.param_vector(s.plant_overrides, s.plant_scale) for s in distinct])
    # a change at t = 0 applies from the start
    scen_d = np.stack([s.row() for s in distinct])
    x0_d = np.zeros((len(distinct), n))
    for j, s in enumerate(distinct):
        if s.x0:
            if len(s.x0) != n:
                raise ValueError(f"scenario.x0 has {len(s.x0)} entries; plant has {n} states")
            x0_d[j] = s.x0
    n_noise = max(ceil(t_final / s.noise_hold) + 2 for s in distinct)
    noise_d = np.stack(
        [
            noise_sequence(s.noise_seed, n_noise) if s.noise_variance > 0 else np.zeros(n_noise)
            for s in distinct
        ]
    )
    n_ref = max([len(s.reference.samples) for s in distinct] + [2])
    ref_d = np.zeros((len(distinct), n_ref))
    for j, s in enumerate(distinct):
        if s.reference.samples:
            ref_d[j, : len(s.reference.samples)] = s.reference.samples
            ref_d[j, len(s.reference.samples) :] = s.reference.samples[-1]

    kernel = kernel_for(plant)
    n_save = n_steps // decimation + 1 if store else 0
    traj = np.full((b, n_save, kernel.n_cols), np.nan)
    metrics = np.zeros((b, L.N_METRIC))
    status = np.zeros(b, dtype=np.int64)
    t_div = np.zeros(b)
    kernel(
        batch.ints,
        batch.floats,
        np.ascontiguousarray(p_before_d[rows]),
        np.ascontiguousarray(p_after_d[rows]),
        p_nom,
        np.ascontiguousarray(scen_d[rows]),
        np.ascontiguousarray(x0_d[rows]),
        ref_d,
        rows,
        noise_d,
        rows,
        float(dt),
        n_steps,
        L.METHODS[method],
        int(decimation),
        bool(store),
        float(divergence_threshold),
        metrics,
        status,
        t_div,
        traj,
    )
    return BatchResult(
        metrics=metrics,
        diverged=status == L.STATUS_DIVERGED,
        diverged_at=t_div,
        trajectories=traj if store else None,
        columns=L.trajectory_columns(n),
        dt=float(dt),
    )


def simulate(
    plant: Plant,
    controller: Controller,
    scenario: Scenario,
    *,
    dt: float = 1e-4,
    method: str = "rk4",
    store: bool = True,
    decimation: int = 10,
    divergence_threshold: float = 1e10,
) -> SimulationResult:
    """Simulate one closed loop (a batch of one). See :func:`simulate_batch`."""
    res = simulate_batch(
        plant,
        controller,
        scenario,
        dt=dt,
        method=method,
        store=store,
        decimation=decimation,
        divergence_threshold=divergence_threshold,
    )
    return res.member(0)
