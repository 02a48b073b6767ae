r"""The closed loop of the analyses as one compiled description: settings and calls.

:class:`CompiledLoop` holds one :class:`~aiofl.analysis.closed_loop.ClosedLoop`'s
settings as the arrays the compiled kernel :func:`aiofl.analysis.loop_kernel.loop_eval`
reads, evaluates the plant's functions and Jacobians (compiled,
:mod:`aiofl.analysis.plant_jets`, or from Python where they cannot be) and calls the
kernel: the right-hand side, its exact Jacobian in the state, the linear model
:math:`(A, B, C, D)` with the inputs' columns, the output row and the non-smooth
functions' input rows.  :class:`ClosedLoop` (linearisation, margins, the sampled loop) and
:class:`~aiofl.analysis.orbit_loop.OrbitLoop` (orbits, Floquet multipliers, Lyapunov
exponents, harmonic balance) evaluate their loop through it; ``ClosedLoop.rhs`` stays the
Python reference (complex-step safe) the tests compare it with.
"""

from __future__ import annotations

import functools
from typing import Any

import numpy as np
from numpy.typing import NDArray

from aiofl.analysis.loop_kernel import (
    F_B0,
    F_DINJ,
    F_GA,
    F_GB,
    F_ITD_BOC,
    F_ITD_GAIN,
    F_ITD_RR,
    F_KA,
    F_KB,
    F_KINJ,
    F_UMAX,
    F_UMIN,
    F_VL,
    I_BD,
    I_ESO,
    I_LAW,
    I_M,
    I_N,
    I_NL,
    I_NTD,
    I_RHO,
    I_SEF,
    I_TD,
    LAW_AIOFL,
    LAW_IOFL,
    LAW_MODEL,
    N_INTS,
    TD_EXACT,
    TD_HAN,
    TD_IMPROVED,
    TD_LINEAR,
    float_offsets,
    loop_eval,
)

__all__ = ["JET_RTOL", "CompiledLoop"]

JET_RTOL = 1e-9
"""The compiled plant jets are used when they equal the Python complex step's to this,
relative to max(1, |value|), at the first state evaluated."""


class CompiledLoop:
    r"""The settings of one :class:`~aiofl.analysis.closed_loop.ClosedLoop` for
    :func:`loop_eval`, and the calls: values, and derivatives along tangents.

    Parameters
    ----------
    loop
        A :class:`~aiofl.analysis.closed_loop.ClosedLoop` in ``"linearise"`` mode (or an
        :class:`~aiofl.analysis.orbit_loop.OrbitLoop`); its plant's derivatives
        (``loop.derivatives``) give the plant's Jacobians.
    nl_mode
        How the non-smooth scalars are evaluated: 0 secant gains, 1 exact with their
        slopes, 2 the describing gains of :meth:`evaluate`.
    """

    def __init__(self, loop: Any, nl_mode: int = 0) -> None:
        c = loop.controller
        self.loop = loop
        self.nl_mode = nl_mode
        n, rho, m = loop.n, loop.rho, loop.m
        self.n, self.rho, self.m, self.n_z = n, rho, m, loop.n_z
        td = {"exact": TD_EXACT, "han": TD_HAN, "improved": TD_IMPROVED, "linear": TD_LINEAR}
        if c.law == "iofl":
            law = LAW_IOFL
        elif c.eso_model == "nominal":
            law = LAW_MODEL
        else:
            law = LAW_AIOFL
        sef = {"linear": 0, "nonlinear": 1, "improved": 2}[c.sef]
        ints = np.zeros(N_INTS, dtype=np.int64)
        ints[[I_N, I_NTD, I_RHO, I_M, I_TD]] = n, loop.n_td, rho, m, td[c.td]
        ints[[I_ESO, I_SEF, I_LAW, I_NL]] = int(c.eso == "improved"), sef, law, nl_mode
        self.ints = ints
        self.law = law
        *_, size = float_offsets(rho, m)
        flt = np.zeros(size)
        ob, ol, og, os_, op, _ = float_offsets(rho, m)
        flt[F_B0], flt[F_UMIN], flt[F_UMAX] = loop.b0, loop.u_min, loop.u_max
        flt[ob : ob + rho + 1] = loop.betas
        flt[ol : ol + rho] = loop.lin_k[:rho]
        if c.eso == "improved":
            flt[F_KINJ] = getattr(loop, "k_inj", 0.0)
            keys = ("eso.k_alpha", "eso.k_beta", "eso.g_alpha", "eso.g_beta")
            flt[[F_KA, F_KB, F_GA, F_GB]] = [c.value(key) for key in keys]
        if law != LAW_IOFL and sef:
            if hasattr(loop, "k_sef"):
                flt[og : og + m] = loop.k_sef
            names = ("k", "alpha", "delta", "") if sef == 1 else ("k", "kb", "mu", "alpha")
            for i in range(m):
                for j, name in enumerate(names):
                    if name:
                        flt[os_ + 4 * i + j] = c.value(f"sef.{name}{i + 1}")
            if sef == 2:
                flt[F_VL] = c.value("sef.v_limit")
        if c.td == "improved":
            flt[F_ITD_BOC], flt[F_ITD_GAIN] = loop.itd_constants
            flt[F_ITD_RR] = loop.itd_rho
        if c.td == "linear":
            flt[op : op + rho] = np.asarray(loop.prefilter, dtype=np.float64)[:rho]
        self.flt = flt
        self.has_bd = loop.plant.bd is not None
        self.n_cols = max(n, rho)
        self.n_rows = 1 + 3 * n + 2 + rho + 2
        self.jets: Any = None  # the compiled plant jets, once checked (check_jets)
        self.jets_checked = False
        self.notes: list[str] = []

    def check_jets(self, z: NDArray[np.float64]) -> None:
        """Take the plant's compiled jets (:func:`aiofl.analysis.plant_jets.plant_jets`)
        when their values and Jacobians at z equal the Python complex step's
        (:meth:`aiofl.analysis.derivatives.PlantDerivatives.jet`, checked first against
        finite differences there: :meth:`ClosedLoop.verify_derivatives`) to
        :data:`JET_RTOL`; else keep the Python path (noted)."""
        from aiofl.analysis.plant_jets import plant_jets

        self.jets_checked = True
        self.loop.verify_derivatives(z)
        jets = plant_jets(self.loop.plant)
        if jets is None:
            self.notes.append(
                "plant functions not compiled for complex numbers: the loop takes the "
                "plant's Jacobians from Python (complex step or finite differences)"
            )
            return
        py = self._python_jets(z, self.has_bd, jac=True)
        self.jets = jets
        if not self._jets_exact():
            self.jets = None
            return
        cj = self.plant_jets(z, self.has_bd, jac=True)
        for ref, got in zip(py, cj, strict=True):
            scale = np.maximum(np.abs(ref), 1.0)
            if not np.all(np.abs(got - ref) <= JET_RTOL * scale):
                self.jets = None
                self.notes.append(
                    "the plant's compiled jets differ from the Python complex step by "
                    f"{float(np.max(np.abs(got - ref) / scale)):.3g} (relative): not used"
                )
                return

    def _needed(self) -> list[str]:
        """The plant functions this loop evaluates."""
        names = ["h", "f", "g"] + (["bd"] if self.has_bd else [])
        if self.law == LAW_MODEL:
            names.append("alpha_beta_of_xi")
        if self.law == LAW_IOFL:
            names.append("normal_form")
        return names

    def _jets_exact(self) -> bool:
        """Whether every function the loop needs is differentiated by the complex step in
        Python too (one sent to finite differences is not trusted compiled either)."""
        method = self.loop.derivatives.method
        return all(method.get(name) == "complex step" for name in self._needed())

    def with_describing(self, gains: Any) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
        """The settings with the describing gains ``gains`` (one per SEF term, then the
        injection's) in place of the non-smooth functions (nl_mode 2)."""
        ints, flt = self.ints.copy(), self.flt.copy()
        ints[I_NL] = 2
        _, _, og, *_ = float_offsets(self.rho, self.m)
        g = list(gains)
        if self.ints[I_SEF] and self.law != LAW_IOFL:
            flt[og : og + self.m] = g[: self.m]
        if self.ints[I_ESO]:
            flt[F_DINJ] = g[-1]
        return ints, flt

    def plant_jets(
        self, z: NDArray[np.float64], need_bd: bool, jac: bool
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The plant functions' values (and with ``jac`` their Jacobians) at z's plant
        state and observer state, stacked as :func:`loop_eval` reads them: from the
        compiled jets once checked (:meth:`check_jets`), else from Python.

        Parameters
        ----------
        z
            The loop's state.
        need_bd
            Evaluate the disturbance input b_d too.
        jac
            Take the Jacobians too.

        Returns
        -------
        pv, pj
            The stacked values (rows) and Jacobians (rows × max(n, ρ)).
        """
        if self.jets is None or (jac and not self._jets_exact()):
            return self._python_jets(z, need_bd, jac)
        lp, n, rho = self.loop, self.n, self.rho
        pv = np.zeros(self.n_rows)
        pj = np.zeros((self.n_rows, self.n_cols))
        flags = np.array(
            [jac, need_bd, self.law == LAW_MODEL, self.law == LAW_IOFL], dtype=np.int64
        )
        x = np.ascontiguousarray(z[:n])
        xi = np.ascontiguousarray(z[lp.o_eso : lp.o_eso + rho])
        self.jets(x, xi, lp.p_true, lp.p_nom, flags, pv, pj)
        return pv, pj

    def _python_jets(
        self, z: NDArray[np.float64], need_bd: bool, jac: bool
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """:meth:`plant_jets` from :class:`~aiofl.analysis.derivatives.PlantDerivatives`."""
        lp, n, rho = self.loop, self.n, self.rho
        der = lp.derivatives
        pv = np.zeros(self.n_rows)
        pj = np.zeros((self.n_rows, self.n_cols))
        x = np.ascontiguousarray(z[:n])
        rows = [("h", 0, x, lp.p_true), ("f", 1, x, lp.p_true), ("g", 1 + n, x, lp.p_true)]
        if need_bd:
            rows.append(("bd", 1 + 2 * n, x, lp.p_true))
        if self.law == LAW_MODEL:
            xi = np.ascontiguousarray(z[lp.o_eso : lp.o_eso + rho])
            rows.append(("alpha_beta_of_xi", 1 + 3 * n, xi, lp.p_nom))
        if self.law == LAW_IOFL:
            rows.append(("normal_form", 3 + 3 * n, x, lp.p_nom))
        for name, r0, arg, p in rows:
            if jac:
                value, jm = der.jet(name, arg, p)
                pj[r0 : r0 + value.size, : arg.size] = jm
            else:
                value = der._real(name, arg, p)
            pv[r0 : r0 + value.size] = value
        return pv, pj

    def evaluate(
        self,
        z: NDArray[np.float64],
        rd: Any = None,
        d: Any = None,
        noise: float = 0.0,
        u_plant: Any = None,
        tangents: tuple[Any, Any, Any] | None = None,
        settings: tuple[NDArray[np.int64], NDArray[np.float64]] | None = None,
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        r"""``(out, tout)`` of :func:`loop_eval` at z.

        Parameters
        ----------
        z
            The state.
        rd, d, noise, u_plant
            As for :meth:`ClosedLoop.rhs` (real).
        tangents
            ``(tz, trd, tin)``: the tangents of z (n_z, K), of the reference (ρ+1, K) and of
            (τ_d, n, u_p) (3, K); None: values only.
        settings
            ``(ints, flt)`` in place of this loop's (:meth:`with_describing`).

        Returns
        -------
        out, tout
            Rows ż, y, u, the non-smooth functions' inputs; and their tangents.
        """
        lp, rho = self.loop, self.rho
        z = np.asarray(z, dtype=np.float64)
        rdv = np.zeros(rho + 1)
        if rd is None:
            rdv[0] = lp.r_op
        else:
            rda = np.asarray(rd, dtype=np.float64).reshape(-1)[: rho + 1]
            rdv[: rda.size] = rda
        dd = lp.d_op if d is None else float(d)
        if tangents is None:
            k = 0
            tz, trd, tin = np.zeros((self.n_z, 0)), np.zeros((rho + 1, 0)), np.zeros((3, 0))
        else:
            tz, trd, tin = (np.ascontiguousarray(t, dtype=np.float64) for t in tangents)
            k = tz.shape[1]
        need_bd = self.has_bd and (dd != 0.0 or bool(np.any(tin[0])))
        if not self.jets_checked:
            self.check_jets(z)
        pv, pj = self.plant_jets(z, need_bd, jac=k > 0 and bool(np.any(tz)))
        inputs = np.array([dd, float(noise), 0.0 if u_plant is None else float(u_plant)])
        ints, flt = settings or (self.ints, self.flt)
        if need_bd != bool(ints[I_BD]):
            ints = ints.copy()
            ints[I_BD] = int(need_bd)
        out = np.empty(self.n_z + 3 + self.m)
        tout = np.empty((out.size, k))
        loop_eval(z, tz, rdv, trd, inputs, tin, u_plant is not None, ints, flt, pv, pj, out, tout)
        return out, tout

    def rhs(
        self, z: NDArray[np.float64], rd: Any = None, d: Any = None, noise: float = 0.0
    ) -> NDArray[np.float64]:
        """ż at z (real), compiled: the integrators' call, with buffers kept between calls.

        Parameters
        ----------
        z
            The state.
        rd, d, noise
            As for :meth:`evaluate`.

        Returns
        -------
        ndarray
            Shape (n_z,).
        """
        lp = self.loop
        z = np.ascontiguousarray(z, dtype=np.float64)
        if not self.jets_checked:
            self.check_jets(z)
        dd = lp.d_op if d is None else float(d)
        need_bd = self.has_bd and dd != 0.0
        if self.jets is None:
            return self.evaluate(z, rd, dd, noise)[0][: self.n_z]
        b = self._buffers
        rdv = b["rd"]
        if rd is None:
            rdv[:] = 0.0
            rdv[0] = lp.r_op
        else:
            rda = np.asarray(rd, dtype=np.float64).reshape(-1)[: self.rho + 1]
            rdv[rda.size :] = 0.0
            rdv[: rda.size] = rda
        inputs = b["inputs"]
        inputs[0], inputs[1] = dd, noise
        flags = b["flags"]
        flags[1] = need_bd
        pv, pj = b["pv"], b["pj"]
        n = self.n
        self.jets(z[:n], z[lp.o_eso : lp.o_eso + self.rho], lp.p_true, lp.p_nom, flags, pv, pj)
        ints = b["ints_bd"] if need_bd else self.ints
        out = b["out"]
        loop_eval(
            z,
            b["tz"],
            rdv,
            b["trd"],
            inputs,
            b["tin"],
            False,
            ints,
            self.flt,
            pv,
            pj,
            out,
            b["tout"],
        )
        return out[: self.n_z].copy()

    @functools.cached_property
    def _buffers(self) -> dict[str, NDArray[Any]]:
        """Arrays :meth:`rhs` fills on every call (values only: no tangents)."""
        ints_bd = self.ints.copy()
        ints_bd[I_BD] = 1
        flags = np.array([0, 0, self.law == LAW_MODEL, self.law == LAW_IOFL], dtype=np.int64)
        return {
            "rd": np.zeros(self.rho + 1),
            "inputs": np.zeros(3),
            "flags": flags,
            "pv": np.zeros(self.n_rows),
            "pj": np.zeros((self.n_rows, self.n_cols)),
            "ints_bd": ints_bd,
            "out": np.empty(self.n_z + 3 + self.m),
            "tz": np.zeros((self.n_z, 0)),
            "trd": np.zeros((self.rho + 1, 0)),
            "tin": np.zeros((3, 0)),
            "tout": np.zeros((self.n_z + 3 + self.m, 0)),
        }

    def state_jacobian(
        self,
        z: NDArray[np.float64],
        rd: Any = None,
        d: Any = None,
        settings: tuple[NDArray[np.int64], NDArray[np.float64]] | None = None,
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        r"""``(out, J)`` at z: the values and :math:`\partial(\dot z, y, u, e)/\partial z`
        (rows as :meth:`evaluate`'s, n_z columns).

        Parameters
        ----------
        z
            The state.
        rd, d
            The reference (and derivatives) and the disturbance, as for :meth:`evaluate`.
        settings
            As for :meth:`evaluate`.

        Returns
        -------
        out, J
        """
        nz, rho = self.n_z, self.rho
        tangents = (np.eye(nz), np.zeros((rho + 1, nz)), np.zeros((3, nz)))
        return self.evaluate(z, rd, d, tangents=tangents, settings=settings)

    def linear_model(
        self, z: NDArray[np.float64], *, broken: bool = False
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        r"""Exact Jacobians :math:`(A, B, C, D)` at z (as
        :meth:`aiofl.analysis.closed_loop.ClosedLoop.linear_model`): one call with the
        tangents of the state and of the inputs (r and its derivatives, τ_d, n; or, with
        ``broken``, the plant's input u_p held at the controller's u*).

        Parameters
        ----------
        z
            The operating point.
        broken
            The loop broken at the plant input.

        Returns
        -------
        A, B, C, D
        """
        lp, nz, rho = self.loop, self.n_z, self.rho
        v = lp.operating_inputs()
        n_ref = lp.n_ref
        n_in = 1 if broken else v.size
        tz = np.zeros((nz, nz + n_in))
        tz[:, :nz] = np.eye(nz)
        trd = np.zeros((rho + 1, nz + n_in))
        tin = np.zeros((3, nz + n_in))
        u_star = None
        if broken:
            u_star = float(self.evaluate(z)[0][nz + 1])
            tin[2, nz] = 1.0
        else:
            for j in range(n_ref):
                trd[j, nz + j] = 1.0
            tin[0, nz + n_ref] = 1.0
            tin[1, nz + n_ref + 1] = 1.0
        rd = v[:n_ref]
        d, noise = v[n_ref], v[n_ref + 1]
        _, jac = self.evaluate(z, rd, d, noise, u_star, tangents=(tz, trd, tin))
        a, b = jac[:nz, :nz], jac[:nz, nz:]
        c, dd = jac[nz : nz + 2, :nz], jac[nz : nz + 2, nz:]
        if broken:  # output: the controller's u only
            return a, b, c[1:], dd[1:]
        return a, b, c, dd

    def output_row(self, z: NDArray[np.float64]) -> NDArray[np.float64]:
        r""":math:`\partial y/\partial z` at z."""
        return self.state_jacobian(z)[1][self.n_z]

    def outputs(self, zs: NDArray[np.float64]) -> tuple[NDArray[Any], NDArray[Any]]:
        """(y, u) at each column of ``zs`` (the operating inputs)."""
        vals = [self.evaluate(z)[0] for z in np.asarray(zs, dtype=np.float64).T]
        return np.array([v[self.n_z] for v in vals]), np.array([v[self.n_z + 1] for v in vals])

    def error_rows(self, jac: NDArray[np.float64]) -> NDArray[np.float64]:
        """The rows of ``jac`` (:meth:`state_jacobian`'s) of the non-smooth functions'
        inputs, in :meth:`aiofl.analysis.orbit_loop.OrbitLoop.nonlinearities` order: the
        SEF errors (law AIOFL, fal or INLSEF), then the INLESO's injection error."""
        ie = self.n_z + 2
        rows = []
        if self.law != LAW_IOFL and self.ints[I_SEF]:
            rows += [ie + i for i in range(self.m)]
        if self.ints[I_ESO]:
            rows.append(ie + self.m)
        return jac[rows]
