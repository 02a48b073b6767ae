r"""Radau IIA over the compiled closed loop: the Python side of
:mod:`aiofl.analysis.radau_kernel`.

:class:`LoopIntegrator` integrates an :class:`~aiofl.analysis.orbit_loop.OrbitLoop`'s
:math:`\dot z = F(t, z)` (and, for the variational equation, Φ along it) in compiled slices
of :data:`SLICE` steps, checking the analysis' time budget between them
(:func:`aiofl.analysis.budget.check_budget`); the result is a :class:`RadauSolution`, read
as scipy's ``solve_ivp`` result (``t``, ``y``, ``sol``).  The slice is one compiled entry
for every plant: the plant's jets and the loop kernel are passed to it as first-class
functions of a fixed signature (:func:`compiled_slice`).
:mod:`aiofl.analysis.variational` uses it when the right-hand side carries it
(``f.integrator``, set by :meth:`aiofl.analysis.orbit_loop.OrbitLoop.field`), else scipy.
"""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np
from numba import njit, types
from numpy.typing import NDArray

from aiofl.analysis.budget import check_budget
from aiofl.analysis.radau_kernel import (
    DONE,
    K_HAN,
    K_HOLD,
    K_SAMPLES,
    K_SINE,
    K_STEP,
    RUNNING,
    SF_AMP,
    SF_D,
    SF_DAMP,
    SF_DTIME,
    SF_OFFSET,
    SF_OMEGA,
    SF_PHASE,
    SF_ROP,
    SF_TSTEP,
    TOO_SMALL,
    run_slice,
)

__all__ = ["PHI_PARTS", "SLICE", "LoopIntegrator", "RadauSolution", "compiled_slice"]

SLICE = 400
"""Steps per compiled call; the time budget is checked between calls."""
PHI_PARTS = 8
"""Exponential-midpoint parts per Radau step at least (``split`` of
:func:`aiofl.analysis.variational.variational_flow` when larger): Radau's steps of order 5
are longer than BDF's, and the midpoint rule's error grows with the step (frontier-s1-leso's
largest multiplier at the report's settings: 0.10 with one part, 0.71 with 4, 0.69 with 16;
scipy's BDF with one part per its steps: 0.56, a loop whose orbit does not close)."""


# --------------------------------------------------------------------- the Python side
def _signature() -> Any:
    """The compiled entry's signature: the plant's jets and the loop kernel as first-class
    functions (one compiled entry serves every plant)."""
    a1, a2, a3 = types.float64[::1], types.float64[:, ::1], types.float64[:, :, ::1]
    i1 = types.int64[::1]
    jets = types.FunctionType(types.none(a1, a1, a1, a1, i1, a1, a2))
    kernel = types.FunctionType(
        types.none(a1, a2, a1, a2, a1, a2, types.boolean, i1, a1, a1, a2, a1, a2)
    )
    i8, f8 = types.int64, types.float64
    return i8(
        jets, kernel, i1, i1, a1, a1, a1, i1, a1, a2, i8, i8, i8,
        a1, f8, f8, f8, a1, a1, a2, a1, i8, a1, a2, a3,
    )  # fmt: skip


_ENTRY: list[Any] = []


def compiled_slice() -> Any:
    """:func:`aiofl.analysis.radau_kernel.run_slice` compiled for :func:`_signature`
    (compiled, or loaded from numba's disk cache, on first use)."""
    if not _ENTRY:
        from numba.core.errors import NumbaExperimentalFeatureWarning

        with warnings.catch_warnings():  # first-class functions: "experimental" in numba
            warnings.simplefilter("ignore", NumbaExperimentalFeatureWarning)
            _ENTRY.append(njit(_signature(), cache=True)(run_slice))
    return _ENTRY[0]


class RadauSolution:
    """A trajectory: the steps' times ``t`` (m+1,), states ``y`` (n, m+1) and each step's
    collocation polynomial; :meth:`sol` evaluates it (as scipy's ``OdeSolution``)."""

    def __init__(self, t: NDArray[np.float64], y: NDArray[np.float64], q: NDArray[np.float64]):
        """Parameters
        ----------
        t, y
            Times and states at the steps (states as columns).
        q
            Per step, the polynomial's coefficients (m, n, 3).
        """
        self.t, self.y, self.q = t, y, q
        self.success = True

    def sol(self, ts: Any) -> NDArray[np.float64]:
        """The states at the times ``ts`` (scalar: (n,); array: (n, len))."""
        tv = np.atleast_1d(np.asarray(ts, dtype=np.float64))
        i = np.clip(np.searchsorted(self.t, tv, side="right") - 1, 0, self.t.size - 2)
        x = (tv - self.t[i]) / (self.t[i + 1] - self.t[i])
        powers = np.stack([x, x * x, x * x * x])  # (3, len)
        out = self.y[:, i] + np.einsum("kic,ck->ik", self.q[i], powers)
        return out[:, 0] if np.ndim(ts) == 0 else out


class LoopIntegrator:
    """Radau IIA over one :class:`~aiofl.analysis.orbit_loop.OrbitLoop` (module docstring),
    with the reference held (``hold``) or followed, and a held disturbance ``d`` (None: the
    scenario's step).

    Parameters
    ----------
    loop
        The orbit loop.
    hold, d
        As for :meth:`aiofl.analysis.orbit_loop.OrbitLoop.field`.
    """

    def __init__(self, loop: Any, *, hold: bool, d: float | None) -> None:
        self.loop, self.hold, self.d = loop, hold, d

    def usable(self, z: NDArray[np.float64]) -> bool:
        """Whether the compiled path applies: the plant's compiled jets are checked and
        exact (the first Jacobian of the loop checks them, at z) and no describing gains
        are set."""
        lp = self.loop
        if lp.describing is not None:
            return False
        if not lp.compiled.jets_checked:
            lp.jacobian_at(np.asarray(z, dtype=np.float64))
        cl = lp.compiled
        return cl.jets is not None and cl._jets_exact()

    def _spec(self) -> tuple[NDArray[np.int64], NDArray[np.float64], NDArray[np.float64]]:
        """The inputs' description for the compiled field (:func:`_inputs`)."""
        from aiofl.analysis.loop_kernel import LAW_IOFL, LAW_MODEL

        lp = self.loop
        ref = lp.scenario.reference
        tab = np.zeros((3, 1))
        if self.hold:
            kind = K_HOLD
        elif lp.controller.td == "han":
            if lp._han is None:
                raise ValueError("call han_signal(t0, t1) first")
            kind = K_HAN
            _, _, ts, sig = lp._han
            tab = np.ascontiguousarray(np.vstack([ts, sig[0], sig[1]]))
        else:
            kind = {"sine": K_SINE, "step": K_STEP, "samples": K_SAMPLES}[ref.kind]
            if kind == K_SAMPLES:
                samples = np.asarray(ref.samples, dtype=np.float64)
                grid = np.arange(samples.size) * ref.sample_dt
                tab = np.ascontiguousarray(np.vstack([grid, samples, samples]))
        cl = lp.compiled
        spec_i = np.array(
            [
                kind,
                self.d is not None,
                cl.has_bd,
                cl.law == LAW_MODEL,
                cl.law == LAW_IOFL,
                lp.n,
                lp.o_eso,
                lp.rho,
                lp.n_z,
                tab.shape[1],
            ],
            dtype=np.int64,
        )
        sc = lp.scenario
        spec_f = np.zeros(9)
        spec_f[SF_ROP] = lp.r_op
        spec_f[SF_D] = 0.0 if self.d is None else float(self.d)
        spec_f[SF_DAMP], spec_f[SF_DTIME] = sc.disturbance_amplitude, sc.disturbance_time
        for i, name in ((SF_AMP, "amplitude"), (SF_OMEGA, "omega"), (SF_PHASE, "phase")):
            spec_f[i] = float(getattr(ref, name, 0.0) or 0.0)
        spec_f[SF_OFFSET] = float(getattr(ref, "offset", 0.0) or 0.0)
        spec_f[SF_TSTEP] = float(getattr(ref, "t_step", 0.0) or 0.0)
        return spec_i, spec_f, tab

    def integrate(
        self,
        z0: NDArray[np.float64],
        t0: float,
        t1: float,
        *,
        atol: NDArray[np.float64],
        rtol: float,
        phi: NDArray[np.float64] | None = None,
        dscale: NDArray[np.float64] | None = None,
        split: int = 1,
    ) -> tuple[RadauSolution, NDArray[np.float64] | None]:
        """Integrate from (t0, z0) to t1 (and Φ, scaled by ``dscale``, along, when given).

        Parameters
        ----------
        z0, t0, t1
            The start and the interval [s].
        atol, rtol
            The tolerances (absolute per state).
        phi
            Φ(t0) in the coordinates z / dscale (n × k), or None.
        dscale
            The scaling of Φ's coordinates.
        split
            Exponential-midpoint parts per step (at least :data:`PHI_PARTS`).

        Returns
        -------
        solution, phi
            The trajectory and Φ(t1) (None without ``phi``).

        Raises
        ------
        ArithmeticError
            The step size fell below the smallest at t (the integration failed).
        aiofl.analysis.budget.BudgetExceeded
            The analysis' time budget was spent.
        """
        lp = self.loop
        cl = lp.compiled
        spec_i, spec_f, tab = self._spec()
        z = np.ascontiguousarray(z0, dtype=np.float64).copy()
        nz = z.size
        ph = np.zeros((nz, 0)) if phi is None else np.ascontiguousarray(phi, dtype=np.float64)
        dsc = np.ones(nz) if dscale is None else np.ascontiguousarray(dscale, dtype=np.float64)
        at = np.ascontiguousarray(atol, dtype=np.float64)
        from aiofl.analysis.loop_kernel import I_BD, loop_eval

        ints_bd = cl.ints.copy()
        ints_bd[I_BD] = 1
        ints = cl.ints.copy()
        ints[I_BD] = 0
        run = compiled_slice()
        st = np.array([-1.0, -1.0, -1.0, t0, RUNNING])
        n_out = nz + 3 + lp.m
        ts_all, ys_all, qs_all = [np.array([float(t0)])], [z[:, None]], []
        t = float(t0)
        while True:
            check_budget()
            ts = np.empty(SLICE + 1)
            ys = np.empty((SLICE + 1, nz))
            qs = np.empty((SLICE, nz, 3))
            k = run(
                cl.jets, loop_eval, ints, ints_bd, cl.flt, lp.p_true, lp.p_nom, spec_i,
                spec_f, tab, cl.n_rows, cl.n_cols, n_out, z, t, float(t1), float(rtol), at,
                st, ph, dsc, max(int(split), PHI_PARTS), ts, ys, qs,
            )  # fmt: skip
            ts_all.append(ts[1 : k + 1])
            ys_all.append(ys[1 : k + 1].T)
            qs_all.append(qs[:k])
            if st[4] == TOO_SMALL:
                raise ArithmeticError(
                    f"integration failed: the step size fell below the smallest at t = {st[3]:g}"
                )
            if st[4] == DONE:
                break
            z = ys[k].copy()
            t = float(ts[k])
        sol = RadauSolution(
            np.concatenate(ts_all), np.concatenate(ys_all, axis=1), np.concatenate(qs_all)
        )
        return sol, (None if phi is None else ph)
