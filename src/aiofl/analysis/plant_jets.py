r"""A plant's functions with their exact Jacobians, compiled: the plant part of the loop.

:func:`plant_jets` compiles, once per plant (cached on disk by the engine's compile
factory, :func:`aiofl.engine.build.compile.build`, under a fingerprint of the plant's code and
this file), one function that evaluates the plant's h, f, g, b_d, the model's
:math:`(\alpha, \beta)(\xi)` and the normal form at a real state and, on request, their
Jacobians by the complex step (:mod:`aiofl.analysis.derivatives`), all in compiled code.
:class:`aiofl.analysis.compiled_loop.CompiledLoop` reads them.

The plant's functions are compiled for complex numbers from their Python code with the
names they use re-bound (:func:`complex_function`): ``math`` to a module of :mod:`cmath`'s
functions, ``abs`` / ``math.fabs`` / ``min`` / ``max`` to their complex-step forms (the
branch chosen by the real part), numpy's ``empty`` / ``zeros`` / ``ones`` (and ``_like``)
to complex arrays and its ``tanh`` to :mod:`cmath`'s (numba's overflows to NaN), and the
functions they call (a rig's plant calls the bare plant's compiled functions,
:func:`aiofl.plants.actuated.with_rig`) to their re-bound copies.  A
plant whose code numba cannot compile so (a name outside these) has no compiled jets:
:func:`plant_jets` returns None and the loop takes the plant's Jacobians from
:class:`~aiofl.analysis.derivatives.PlantDerivatives` in Python.  Jets that compile but
whose Jacobian differs from the Python complex step (e.g. ``numpy.abs``, the modulus) are
refused by the loop's first check
(:meth:`~aiofl.analysis.compiled_loop.CompiledLoop.check_jets`).
"""

from __future__ import annotations

import cmath
import math
import threading
import types
from typing import Any

import numpy as np
from numba import literal_unroll, njit
from numba.core import types as nt
from numba.extending import overload

from aiofl.plants.base import Plant

__all__ = ["STEP", "complex_function", "jet_rows", "plant_jets"]

STEP = 1e-30
"""The imaginary step (as :data:`aiofl.analysis.derivatives.COMPLEX_STEP`)."""


# ----------------------------------------------------- complex-step forms of real functions
@njit(cache=True)
def _cabs(x: Any) -> Any:
    """``abs`` on the complex step: ±x by the sign of the real part."""
    return x if x.real >= 0.0 else -x


@njit(cache=True)
def _cmin(a: Any, b: Any) -> Any:
    return a if a.real <= b.real else b


@njit(cache=True)
def _cmax(a: Any, b: Any) -> Any:
    return a if a.real >= b.real else b


@njit(cache=True)
def _ccopysign(x: Any, y: Any) -> Any:
    ax = x if x.real >= 0.0 else -x
    return ax if math.copysign(1.0, y.real) > 0.0 else -ax


@njit(cache=True)
def _ctanh(z: Any) -> Any:
    """tanh of a complex number: numba's ``numpy.tanh`` gives NaN beyond |Re z| ≈ 355
    (its exponentials overflow), :mod:`cmath`'s is ±1 there (a rig's friction
    tanh(v/ε) with a small ε reaches it)."""
    return cmath.tanh(z)


@njit(cache=True)
def _cempty(shape: Any) -> Any:
    return np.empty(shape, np.complex128)


@njit(cache=True)
def _czeros(shape: Any) -> Any:
    return np.zeros(shape, np.complex128)


@njit(cache=True)
def _cones(shape: Any) -> Any:
    return np.ones(shape, np.complex128)


@njit(cache=True)
def _czeros_like(a: Any) -> Any:
    return np.zeros(a.shape, np.complex128)


def _module(name: str, base: Any, extra: dict[str, Any]) -> types.ModuleType:
    mod = types.ModuleType(name)
    mod.__dict__.update({k: v for k, v in vars(base).items() if not k.startswith("__")})
    mod.__dict__.update(extra)
    return mod


_CMATH = _module("aiofl_complex_math", cmath, {"fabs": _cabs, "copysign": _ccopysign})
"""``math`` for a plant function compiled for complex numbers."""
_CNUMPY = _module(
    "aiofl_complex_numpy",
    np,
    {
        "empty": _cempty,
        "zeros": _czeros,
        "ones": _cones,
        "empty_like": _czeros_like,
        "zeros_like": _czeros_like,
        "tanh": _ctanh,
    },
)
"""``numpy`` for a plant function compiled for complex numbers."""
_BY_NAME = {"fabs": _cabs, "copysign": _ccopysign}


def _callee(value: Any) -> bool:
    return isinstance(getattr(value, "py_func", value), types.FunctionType)


def complex_function(fn: Any, memo: dict[int, Any] | None = None) -> Any:
    """``fn`` (a Python function or numba dispatcher) compiled lazily for complex numbers
    (module docstring): a numba dispatcher of its code with the re-bound names.

    Parameters
    ----------
    fn
        The function.
    memo
        Copies already made (by the id of their Python function).

    Returns
    -------
    numba dispatcher
    """
    memo = {} if memo is None else memo
    py = getattr(fn, "py_func", fn)
    if id(py) in memo:
        return memo[id(py)]
    glb = dict(py.__globals__)
    for key, val in py.__globals__.items():
        if val is math:
            glb[key] = _CMATH
        elif val is np:
            glb[key] = _CNUMPY
        elif getattr(val, "__module__", None) == "math" and callable(val):
            name = getattr(val, "__name__", key)
            glb[key] = _BY_NAME.get(name, getattr(cmath, name, val))
        elif _callee(val) and key in py.__code__.co_names and val is not fn:
            glb[key] = complex_function(val, memo)
    glb.update(abs=_cabs, min=_cmin, max=_cmax)
    closure = py.__closure__
    if closure:
        cells = []
        for cell in closure:
            try:
                val = cell.cell_contents
            except ValueError:
                cells.append(cell)
                continue
            cells.append(types.CellType(complex_function(val, memo)) if _callee(val) else cell)
        closure = tuple(cells)
    copy = types.FunctionType(py.__code__, glb, py.__name__, py.__defaults__, closure)
    copy.__qualname__ = f"{py.__qualname__}_complex"
    out = njit(error_model="numpy")(copy)
    memo[id(py)] = out
    return out


# ------------------------------------------------------------------ storing a result
def _store(r: Any, out: Any) -> None:  # pragma: no cover - replaced by its overload
    """A plant function's result (a number, a tuple or an array) into the complex array
    ``out`` (compiled only)."""


@overload(_store)
def _store_overload(r: Any, out: Any) -> Any:
    if isinstance(r, nt.Array):

        def store_array(r: Any, out: Any) -> None:
            for i in range(min(r.size, out.size)):
                out[i] = r[i]

        return store_array
    if isinstance(r, nt.BaseTuple):

        def store_tuple(r: Any, out: Any) -> None:
            i = 0
            for v in literal_unroll(r):
                if i < out.size:
                    out[i] = v
                i += 1  # noqa: SIM113 (numba's literal_unroll has no enumerate)

        return store_tuple

    def store_number(r: Any, out: Any) -> None:
        out[0] = r

    return store_number


# ------------------------------------------------------------------------- the entry
_FH = _FF = _FG = _FBD = _FAB = _FNF = None  # placeholders: the plant's complex functions
_HAS_BD = _HAS_AB = _HAS_NF = False  # placeholders: which of the optional ones it has
_STORE = None  # placeholder: _store
_STEP = 1e-30  # placeholder: STEP


def jet_rows(n: int, rho: int) -> tuple[int, int, int, int, int, int, int]:
    """Rows of h, f, g, b_d, (α, β), the normal form in the stacked values, and their
    number (h: 1, f, g, b_d: n, (α, β): 2, the normal form: ρ + 2)."""
    r_f = 1
    r_g = r_f + n
    r_bd = r_g + n
    r_ab = r_bd + n
    r_nf = r_ab + 2
    return 0, r_f, r_g, r_bd, r_ab, r_nf, r_nf + rho + 2


def _tpl_put(buf, size, j, r0, pv, pj):  # pragma: no cover - compiled
    """The stored result's values (j < 0) or Jacobian column j into rows r0.. ."""
    for i in range(size):
        if j < 0:
            pv[r0 + i] = buf[i].real
        else:
            pj[r0 + i, j] = buf[i].imag / _STEP


def _tpl_jets(x, xi, p_true, p_nom, flags, pv, pj):  # pragma: no cover - compiled
    """The plant's values at (x, ξ) into ``pv`` and, with ``flags[0]``, their Jacobians
    into ``pj`` (rows :func:`jet_rows`); ``flags[1:4]``: evaluate b_d, (α, β), the normal
    form."""
    n = x.size
    rho = xi.size
    r_h, r_f = 0, 1  # the rows of jet_rows (a template sees only its bindings)
    r_g = r_f + n
    r_bd = r_g + n
    r_ab = r_bd + n
    r_nf = r_ab + 2
    cols = n if flags[0] != 0 else 0
    buf = np.zeros(max(n, rho + 2, 2), np.complex128)
    xc = np.empty(n, np.complex128)
    for j in range(-1, cols):
        for q in range(n):
            xc[q] = x[q]
        if j >= 0:
            xc[j] = complex(x[j], _STEP)
        buf[:] = 0.0
        _STORE(_FH(xc, p_true), buf[:1])
        _PUT(buf, 1, j, r_h, pv, pj)
        _STORE(_FF(xc, p_true), buf[:n])
        _PUT(buf, n, j, r_f, pv, pj)
        buf[:] = 0.0
        _STORE(_FG(xc, p_true), buf[:n])
        _PUT(buf, n, j, r_g, pv, pj)
        if _HAS_BD and flags[1] != 0:
            buf[:] = 0.0
            _STORE(_FBD(xc, p_true), buf[:n])
            _PUT(buf, n, j, r_bd, pv, pj)
        if _HAS_NF and flags[3] != 0:
            buf[:] = 0.0
            _STORE(_FNF(xc, p_nom), buf[: rho + 2])
            _PUT(buf, rho + 2, j, r_nf, pv, pj)
    if _HAS_AB and flags[2] != 0:
        xic = np.empty(n, np.complex128)
        for j in range(-1, rho if flags[0] != 0 else 0):
            for q in range(n):
                xic[q] = xi[q] if q < rho else 0.0
            if j >= 0:
                xic[j] = complex(xi[j], _STEP)
            buf[:] = 0.0
            _STORE(_FAB(xic, p_nom), buf[:2])
            _PUT(buf, 2, j, r_ab, pv, pj)


_PUT = None  # placeholder: _tpl_put compiled

_JETS: dict[int, tuple[Plant, Any]] = {}
_LOCK = threading.Lock()


def plant_jets(plant: Plant, *, cache: bool = True) -> Any:
    """The compiled jets of ``plant`` (module docstring), or None when its functions cannot
    be compiled for complex numbers.  Compiled (or loaded from the disk cache) on the first
    call in a process and kept; the first call runs them once, so a failure shows here.

    Parameters
    ----------
    plant
        The plant.
    cache
        Use the disk cache.

    Returns
    -------
    numba dispatcher or None
        ``jets(x, xi, p_true, p_nom, flags, pv, pj)``.
    """
    from numba.core.errors import NumbaError

    from aiofl.engine.build import compile as compile_

    key = id(plant)
    with _LOCK:
        if key in _JETS and _JETS[key][0] is plant:
            return _JETS[key][1]
        memo: dict[int, Any] = {}
        fns = {"_FH": plant.h, "_FF": plant.f, "_FG": plant.g}
        opt = {"_FBD": plant.bd, "_FAB": plant.alpha_beta_of_xi, "_FNF": plant.normal_form}
        try:
            own: dict[str, Any] = {k: complex_function(v, memo) for k, v in fns.items()}
            for k, v in opt.items():
                own[k] = complex_function(v, memo) if v is not None else None
            own.update(_HAS_BD=plant.bd is not None, _HAS_AB=plant.alpha_beta_of_xi is not None)
            own["_HAS_NF"] = plant.normal_form is not None
            recipe = compile_.Recipe(
                kind="jets",
                plant=plant,
                bindings={"__name__": __name__, "np": np, "_STORE": _store, "_STEP": STEP},
                templates=(compile_.Template("_PUT", _tpl_put, {"error_model": "numpy"}),),
                entry=compile_.Template("_JETS", _tpl_jets, {"error_model": "numpy"}, own),
                sources=(__file__,),
            )
            jets = compile_.build(recipe, cache=cache).entry
            n = plant.n_states
            rho = plant.relative_degree or 1
            _, *_, rows = jet_rows(n, rho)
            x = np.full(n, 0.1)
            p = plant.param_vector()
            flags = np.ones(4, dtype=np.int64)
            jets(x, x[:rho].copy(), p, p, flags, np.zeros(rows), np.zeros((rows, max(n, rho))))
        except (NumbaError, TypeError, ValueError, AttributeError, IndexError):
            jets = None
        _JETS[key] = (plant, jets)
        return jets
