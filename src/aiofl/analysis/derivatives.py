r"""Exact first derivatives of a plant's functions by the complex step.

The closed-loop Jacobians of :mod:`aiofl.analysis.linearize` are taken by complex-step
differentiation (Squire & Trapp, SIAM Review 40, 1998; Martins, Sturdza & Alonso, ACM TOMS
29, 2003): for a function F analytic near a real point z,

.. math:: F(z + i h e_j) = F(z) + i h\,\frac{\partial F}{\partial z_j}(z) + O(h^2),
          \qquad \frac{\partial F}{\partial z_j}(z)
          = \frac{\operatorname{Im} F(z + i h e_j)}{h} + O(h^2).

There is no subtraction, so h can be tiny (:data:`COMPLEX_STEP` = 1e-30) and the
derivative is exact to rounding, unlike a finite difference whose error (≈1e-7 relative)
splits a repeated eigenvalue into a visible cluster.

The controller's arithmetic is complex-safe (:class:`aiofl.analysis.closed_loop.ClosedLoop`);
a plant's functions are user Python, usually written over :mod:`math` (the generated ones
always are), which refuses complex numbers.  :func:`complex_safe` re-binds a function's
``math`` (and ``from math import ...`` names, ``abs``, ``min``, ``max``) to complex-step
versions: :mod:`cmath` for the analytic functions, and for the piecewise ones the branch
chosen by the real part (``abs(x) = ±x``), which is the derivative of the real function
wherever it has one.  :class:`PlantDerivatives` checks the result against an adaptive
finite-difference Jacobian (:func:`scipy.differentiate.jacobian`) at the operating point;
a function that cannot be evaluated on complex numbers, or whose complex step disagrees
(e.g. a plant calling ``numpy.abs``, the modulus), is differentiated by that finite
difference instead, and the linearisation says so in its notes.
"""

from __future__ import annotations

import builtins
import cmath
import dis
import math
import types
import warnings
from collections import OrderedDict
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["COMPLEX_STEP", "FD_CACHE_SIZE", "PlantDerivatives", "complex_safe"]

try:
    from numba.core.errors import NumbaError
except ImportError:  # pragma: no cover - numba is a dependency

    class NumbaError(Exception):  # type: ignore[no-redef]
        """Stand-in when numba is absent."""


COMPLEX_FAILURES = (TypeError, np.exceptions.ComplexWarning, NumbaError)
"""What a re-bound function raises when it cannot run on complex numbers (a name outside
the complex namespace, a cast dropping an imaginary part, a numba-compiled callee)."""

COMPLEX_STEP = 1e-30
"""Imaginary step h of the complex-step derivative (no cancellation, so any tiny h works)."""

FD_STEPS = (1e-2, 1e-4, 1e-6)
"""First steps of the finite difference, as fractions of max(1, |x_j|), tried in turn until
the Jacobian is finite (a step may reach a point where the plant is not defined)."""

FD_CACHE_SIZE = 256
"""Finite-difference Jacobians a :class:`PlantDerivatives` keeps (the most recently used).
A tangent batch asks for the Jacobian at one real state once per column, so a few entries
serve it; an orbit integration visits ~10⁵ states, and an unbounded cache grew with each."""

_ANALYTIC = (
    "sin", "cos", "tan", "asin", "acos", "atan", "sinh", "cosh", "tanh",
    "asinh", "acosh", "atanh", "exp", "log", "log10", "sqrt",
)  # fmt: skip


def _abs(x: Any) -> Any:
    """``abs`` on the complex step: ±x by the sign of the real part (d|x|/dx = sign x)."""
    if isinstance(x, complex | np.complexfloating):
        return x if x.real >= 0.0 else -x
    if isinstance(x, np.ndarray) and np.iscomplexobj(x):
        return np.where(x.real >= 0.0, x, -x)
    return builtins.abs(x)


def _real(v: Any) -> Any:
    return v.real if isinstance(v, complex | np.complexfloating) else v


def _min(*args: Any, **kw: Any) -> Any:
    items = args[0] if len(args) == 1 else args
    return builtins.min(items, key=_real, **kw)


def _max(*args: Any, **kw: Any) -> Any:
    items = args[0] if len(args) == 1 else args
    return builtins.max(items, key=_real, **kw)


def _copysign(x: Any, y: Any) -> Any:
    return _abs(x) if math.copysign(1.0, _real(y)) > 0 else -_abs(x)


def _atan2(y: Any, x: Any) -> Any:
    yr, xr = _real(y), _real(x)
    yi, xi = complex(y).imag, complex(x).imag
    value = math.atan2(yr, xr)
    if yi == 0.0 and xi == 0.0:
        return value
    return complex(value, (xr * yi - yr * xi) / (xr * xr + yr * yr))


def _hypot(*xs: Any) -> Any:
    return cmath.sqrt(sum(x * x for x in xs))


def _log2(x: Any) -> Any:
    return cmath.log(x) / math.log(2.0)


def _make_math_namespace() -> types.SimpleNamespace:
    ns = types.SimpleNamespace(**{k: getattr(math, k) for k in dir(math) if not k.startswith("_")})
    for name in _ANALYTIC:
        setattr(ns, name, getattr(cmath, name))
    ns.fabs = _abs
    ns.copysign = _copysign
    ns.atan2 = _atan2
    ns.hypot = _hypot
    ns.log2 = _log2
    ns.pow = lambda x, y: x**y
    ns.exp2 = lambda x: cmath.exp(x * math.log(2.0))
    ns.expm1 = lambda x: cmath.exp(x) - 1.0
    ns.log1p = lambda x: cmath.log(1.0 + x)
    return ns


_COMPLEX_MATH = _make_math_namespace()
"""Stand-in for :mod:`math` in a re-bound plant function (functions not listed stay real
and raise on a complex argument, which sends the function to the finite difference)."""


def _complex_dtype(dtype: Any) -> Any:
    """complex128 for numpy's default (float) dtype, else ``dtype``."""
    if dtype is None or dtype is float or np.dtype(dtype) == np.float64:
        return np.complex128
    return dtype


class _ComplexNumpy:
    """:mod:`numpy` for a re-bound plant function: ``empty``, ``zeros``, ``ones`` and their
    ``_like`` forms make complex arrays where numpy would make float ones (a function that
    fills an ``np.empty(n)`` would drop the complex step's imaginary part); the rest is
    numpy's."""

    def __getattr__(self, name: str) -> Any:
        return getattr(np, name)

    @staticmethod
    def empty(shape: Any, dtype: Any = None, **kw: Any) -> Any:
        return np.empty(shape, dtype=_complex_dtype(dtype), **kw)

    @staticmethod
    def zeros(shape: Any, dtype: Any = None, **kw: Any) -> Any:
        return np.zeros(shape, dtype=_complex_dtype(dtype), **kw)

    @staticmethod
    def ones(shape: Any, dtype: Any = None, **kw: Any) -> Any:
        return np.ones(shape, dtype=_complex_dtype(dtype), **kw)

    @staticmethod
    def empty_like(a: Any, dtype: Any = None, **kw: Any) -> Any:
        return np.empty_like(a, dtype=_complex_dtype(dtype), **kw)

    @staticmethod
    def zeros_like(a: Any, dtype: Any = None, **kw: Any) -> Any:
        return np.zeros_like(a, dtype=_complex_dtype(dtype), **kw)


_COMPLEX_NUMPY = _ComplexNumpy()

MAX_DEPTH = 4
"""How deep :func:`complex_safe` follows the functions a function calls (through its
globals and its closure)."""


def _callee(value: Any) -> bool:
    """Whether ``value`` is a function :func:`complex_safe` re-binds when a function calls
    it: a numba dispatcher (its ``py_func``) or a plain Python function."""
    return isinstance(getattr(value, "py_func", value), types.FunctionType)


def _names(code: types.CodeType) -> set[str]:
    """The global names ``code`` and the code nested in it (comprehensions, lambdas) use."""
    out = set(code.co_names)
    for const in code.co_consts:
        if isinstance(const, types.CodeType):
            out |= _names(const)
    return out


def complex_safe(fn: Callable[..., Any], _depth: int = 0) -> Callable[..., Any] | None:
    """A copy of the Python function ``fn`` whose ``math`` evaluates on complex numbers.

    The copy shares ``fn``'s code; its globals are ``fn``'s with the module :mod:`math`,
    every function imported from it, and the built-ins ``abs``, ``min``, ``max`` replaced
    by complex-step versions (module docstring), :mod:`numpy` by one whose array
    constructors make complex arrays, and the functions it calls (numba dispatchers
    through their ``py_func``, Python functions; in its globals and its closure, to
    :data:`MAX_DEPTH` levels) by their re-bound copies: a plant wrapping another plant's
    compiled functions (:func:`aiofl.plants.actuated.with_rig`) is re-bound through them.
    Returns None when ``fn`` has no Python code.
    """
    py = getattr(fn, "py_func", fn)
    code = getattr(py, "__code__", None)
    if code is None or not isinstance(py, types.FunctionType):
        return None
    deeper = _depth < MAX_DEPTH

    def rebound(val: Any) -> Any:
        if deeper and _callee(val) and getattr(val, "py_func", val) is not py:
            return complex_safe(val, _depth + 1) or val
        return val

    glb = dict(py.__globals__)
    used = _names(code)
    for key, val in py.__globals__.items():
        if val is math:
            glb[key] = _COMPLEX_MATH
        elif val is np:
            glb[key] = _COMPLEX_NUMPY
        elif getattr(val, "__module__", None) == "math" and callable(val):
            glb[key] = getattr(_COMPLEX_MATH, getattr(val, "__name__", key), val)
        elif key in used:
            glb[key] = rebound(val)
    glb.update(abs=_abs, min=_min, max=_max)
    closure = py.__closure__
    if closure:
        cells = []
        for cell in closure:
            try:
                val = cell.cell_contents
            except ValueError:  # an empty cell
                cells.append(cell)
                continue
            new = rebound(val)
            cells.append(cell if new is val else types.CellType(new))
        closure = tuple(cells)
    return types.FunctionType(code, glb, py.__name__, py.__defaults__, closure)


_DYNAMIC = frozenset({"locals", "vars", "eval", "exec"})


def reads_first_argument(fn: Callable[..., Any] | None) -> bool:
    """Whether the Python function ``fn`` can depend on its first argument (the state x).

    False only when its code provably never touches it: no instruction loads, stores or
    deletes that local, no nested function captures it, and the code names none of
    ``locals, vars, eval, exec``.  Such a function is constant in x (its Jacobian is 0),
    e.g. a constant input gain g(x) = b.  True for anything without Python code."""
    code = getattr(fn, "__code__", None)
    if code is None or code.co_argcount < 1:
        return True
    name = code.co_varnames[0]
    if name in code.co_cellvars or _DYNAMIC & set(code.co_names):
        return True
    for ins in dis.get_instructions(code):
        if ins.opcode in dis.haslocal or ins.opcode in dis.hasfree:
            args = ins.argval if isinstance(ins.argval, tuple) else (ins.argval,)
            if name in args:
                return True
    return False


def _call_complex(cfn: Callable[..., Any], x: NDArray[Any], p: NDArray[np.float64]) -> NDArray[Any]:
    """``cfn(x, p)`` as a complex array; a cast that would drop an imaginary part (numpy's
    ComplexWarning, e.g. ``math.erf`` of a numpy complex) raises it as an error."""
    with warnings.catch_warnings():
        warnings.simplefilter("error", np.exceptions.ComplexWarning)
        return np.asarray(cfn(x, p), dtype=np.complex128).reshape(-1)


def _step_inputs(x: NDArray[np.float64], columns: Any) -> NDArray[np.complex128]:
    """The complex steps :math:`x + ihe_j`, j in ``columns``, as rows."""
    steps = np.empty((len(columns), x.size), dtype=np.complex128)
    steps[:] = x
    steps[np.arange(len(columns)), np.asarray(columns)] += 1j * COMPLEX_STEP
    return steps


class PlantDerivatives:
    r"""A plant's functions ``f, g, h, bd, normal_form, alpha_beta_of_xi`` on complex states.

    ``evaluate(name, x, p)`` returns the function's value as an array; for a complex x it
    is the complex-step extension :math:`\phi(\operatorname{Re}x) + i\,J_\phi\,\operatorname{Im}x`
    (to first order), from the re-bound function (:func:`complex_safe`) or, for a function
    sent to the finite difference, from :func:`scipy.differentiate.jacobian` at
    :math:`\operatorname{Re}x`.

    Parameters
    ----------
    plant
        A :class:`aiofl.plants.base.Plant`.
    """

    NAMES = ("f", "g", "h", "bd", "normal_form", "alpha_beta_of_xi")

    def __init__(self, plant: Any) -> None:
        self.plant = plant
        self.functions: dict[str, Callable[..., Any]] = {}
        self.complex: dict[str, Callable[..., Any] | None] = {}
        for name in self.NAMES:
            fn = getattr(plant, name)
            if fn is not None:
                self.functions[name] = fn
                self.complex[name] = complex_safe(fn)
        self.reads_state = {name: reads_first_argument(cfn) for name, cfn in self.complex.items()}
        self.method: dict[str, str] = dict.fromkeys(self.functions, "complex step")
        self._verified: set[tuple[bytes, bytes]] = set()
        self.notes: list[str] = []
        self._fd_cache: OrderedDict[tuple[str, bytes, bytes], NDArray[np.float64]] = OrderedDict()

    # ---------------------------------------------------------------- evaluation
    def _real(self, name: str, x: NDArray[np.float64], p: NDArray[np.float64]) -> NDArray[Any]:
        return np.asarray(self.functions[name](x, p), dtype=np.float64).reshape(-1)

    def evaluate(self, name: str, x: NDArray[Any], p: NDArray[np.float64]) -> NDArray[Any]:
        """Value of plant function ``name`` at x (real or complex-step), as a 1-D array; for
        x of shape (n, K) the K columns' values, shape (n_out, K) (:meth:`evaluate_columns`).

        Parameters
        ----------
        name
            The plant function (``"f"``, ``"g"``, ``"h"``, ...).
        x
            The state, shape (n,) or a batch of columns (n, K); real or complex.
        p
            The parameter vector.

        Returns
        -------
        ndarray
            Shape (n_out,), or (n_out, K) for a batch.
        """
        if x.ndim > 1:
            return self.evaluate_columns((name,), x, p)[0]
        if not np.iscomplexobj(x):
            return self._real(name, x, p)
        cfn = self.complex[name]
        if self.method[name] == "complex step" and cfn is not None:
            try:
                return _call_complex(cfn, x, p)
            except COMPLEX_FAILURES as exc:  # outside the namespace
                self._fall_back(name, f"{type(exc).__name__}: {exc}")
        xr = np.ascontiguousarray(x.real)
        jac = self.fd_jacobian(name, xr, p)
        return self._real(name, xr, p) + 1j * (jac @ x.imag)

    # ---------------------------------------------------------------- Jacobians
    def fd_jacobian(
        self, name: str, x: NDArray[np.float64], p: NDArray[np.float64]
    ) -> NDArray[np.float64]:
        """Jacobian of function ``name`` at real x by :func:`scipy.differentiate.jacobian`
        (adaptive central differences with Richardson extrapolation).

        Parameters
        ----------
        name
            The plant function.
        x
            The real state, shape (n,).
        p
            The parameter vector.

        Returns
        -------
        ndarray
            The Jacobian, shape (n_out, n) (cached by x and p).
        """
        key = (name, x.tobytes(), p.tobytes())
        cache = self._fd_cache
        if key in cache:
            cache.move_to_end(key)
            return cache[key]
        jac = np.asarray(self._fd_result(name, x, p).df, dtype=np.float64).reshape(-1, x.size)
        cache[key] = jac
        if len(cache) > FD_CACHE_SIZE:
            cache.popitem(last=False)  # the least recently used
        return jac

    def _fd_result(self, name: str, x: NDArray[np.float64], p: NDArray[np.float64]) -> Any:
        from scipy.differentiate import jacobian

        n = x.size

        def vectorised(xs: NDArray[np.float64]) -> NDArray[np.float64]:
            flat = xs.reshape(n, -1)
            cols = [
                self._real(name, np.ascontiguousarray(flat[:, i]), p) for i in range(flat.shape[1])
            ]
            out = np.stack(cols, axis=-1)
            return out.reshape((out.shape[0], *xs.shape[1:]))

        # a first step of 1 % of max(1, |x|) may reach a point where the function is not
        # finite (the maglev's 1/x1² at x1 = 0.01 m): then smaller steps; the non-finite
        # trials are detected here, not printed as numpy's RuntimeWarnings
        base = np.maximum(1.0, np.abs(x))
        for scale in FD_STEPS:
            with np.errstate(all="ignore"), warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)
                res = jacobian(vectorised, x, initial_step=scale * base)
            if np.all(np.isfinite(res.df)):
                break
        return res

    def complex_jacobian(
        self, name: str, x: NDArray[np.float64], p: NDArray[np.float64]
    ) -> NDArray[np.float64]:
        """Jacobian of function ``name`` at real x by the complex step of the re-bound function.

        Parameters
        ----------
        name
            The plant function.
        x
            The real state, shape (n,).
        p
            The parameter vector.

        Returns
        -------
        ndarray
            The Jacobian, shape (n_out, n).
        """
        return self._call_steps(name, _step_inputs(x, range(x.size)), p).imag / COMPLEX_STEP

    def _call_steps(
        self, name: str, steps: NDArray[np.complex128], p: NDArray[np.float64]
    ) -> NDArray[np.complex128]:
        """The re-bound function at each row of ``steps``, as the columns of an (n_out × rows)
        array, called under one guard that raises numpy's ComplexWarning (as
        :func:`_call_complex`)."""
        cfn = self.complex[name]
        if cfn is None:
            raise TypeError(f"{name} has no Python code to evaluate on complex numbers")
        with warnings.catch_warnings():
            warnings.simplefilter("error", np.exceptions.ComplexWarning)
            values = [cfn(xc, p) for xc in steps]
        return np.array(values, dtype=np.complex128).reshape(len(steps), -1).T

    def evaluate_columns(
        self, names: Sequence[str], x: NDArray[Any], p: NDArray[np.float64]
    ) -> list[NDArray[Any]]:
        r"""Functions ``names`` on the K columns of x (n × K), each of shape (n_out, K).

        A *tangent batch* (complex columns sharing one real point :math:`x_r`, e.g.
        :math:`x_r + ihe_j`) is, to first order in Im x,

        .. math:: \phi(x_r) + i\,J_\phi(x_r)\,\operatorname{Im}x,

        from one complex-step call per perturbed input j (a row of Im x not all 0):
        :math:`J_\phi e_j = \operatorname{Im}\phi(x_r + ihe_j)/h`, the value the real part
        of the first; from a single call for a function that does not read x
        (:func:`reads_first_argument`); for a function sent to the finite difference, the
        real value and :meth:`fd_jacobian`.  These are the numbers :meth:`evaluate` gives
        column by column (to the last bit, where the real part does not move with the step),
        in fewer calls.  Other batches (real, or columns at different real points, or a
        Jacobian that is not finite) are evaluated column by column.

        Parameters
        ----------
        names
            The plant functions to evaluate.
        x
            The states, shape (n, K), real or complex.
        p
            The parameter vector.

        Returns
        -------
        list of ndarray
            One per name, each of shape (n_out, K).
        """
        xr = x.real
        x0 = np.ascontiguousarray(xr[:, 0])
        if x.dtype.kind != "c" or (xr != x0[:, None]).any():
            return [self._column_by_column(name, x, p) for name in names]
        xi = x.imag
        moved = (xi != 0.0).any(axis=1).nonzero()[0]
        if moved.size == 0:
            zero = np.zeros(x.shape[1], dtype=np.complex128)
            return [self._real(name, x0, p)[:, None] + zero for name in names]
        steps, ratio = _step_inputs(x0, moved), xi[moved] / COMPLEX_STEP
        out = []
        for name in names:
            if self.method[name] == "complex step" and self.complex[name] is not None:
                try:
                    if not self.reads_state[name]:  # constant in x: one call serves all
                        values = self._call_steps(name, x0[None, :].astype(np.complex128), p)
                        out.append(np.repeat(values, x.shape[1], axis=1))
                        continue
                    # h·J's columns times Im x / h (exactly 1 on a step of h)
                    values = self._call_steps(name, steps, p)
                    value, jac, weights = values[:, 0].real, values.imag, ratio
                except COMPLEX_FAILURES as exc:  # outside the namespace
                    self._fall_back(name, f"{type(exc).__name__}: {exc}")
            if self.method[name] != "complex step" or self.complex[name] is None:
                value = self._real(name, x0, p)
                jac, weights = self.fd_jacobian(name, x0, p)[:, moved], xi[moved]
            if not np.isfinite(jac).all():  # 0·inf would spread to every column
                out.append(self._column_by_column(name, x, p))
                continue
            col = np.empty((value.size, x.shape[1]), dtype=np.complex128)
            col.real = value[:, None]
            col.imag = jac @ weights
            out.append(col)
        return out

    def jet(
        self, name: str, x: NDArray[np.float64], p: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Value and Jacobian of function ``name`` at real x: the complex step of the
        re-bound function (one call per state; one call for a function that does not read
        x), or for a function sent to the finite difference the real value and
        :meth:`fd_jacobian`.

        Parameters
        ----------
        name
            The plant function.
        x
            The real state (or ξ), shape (n,).
        p
            The parameter vector.

        Returns
        -------
        value, jacobian
            Shapes (n_out,) and (n_out, n).
        """
        if self.method[name] == "complex step" and self.complex[name] is not None:
            try:
                if not self.reads_state[name]:
                    value = self._real(name, x, p)
                    return value, np.zeros((value.size, x.size))
                values = self._call_steps(name, _step_inputs(x, range(x.size)), p)
                return np.ascontiguousarray(values[:, 0].real), values.imag / COMPLEX_STEP
            except COMPLEX_FAILURES as exc:  # outside the namespace
                self._fall_back(name, f"{type(exc).__name__}: {exc}")
        return self._real(name, x, p), self.fd_jacobian(name, x, p)

    def _column_by_column(self, name: str, x: NDArray[Any], p: NDArray[np.float64]) -> NDArray[Any]:
        cols = [self.evaluate(name, np.ascontiguousarray(x[:, k]), p) for k in range(x.shape[1])]
        return np.stack(cols, axis=-1)

    def _fall_back(self, name: str, reason: str) -> None:
        if self.method[name] != "finite difference":
            self.method[name] = "finite difference"
            self.notes.append(
                f"plant function {name}: Jacobian by adaptive finite differences "
                f"(scipy.differentiate.jacobian), not exact; the complex step failed ({reason})"
            )

    def verify(self, x: NDArray[np.float64], p: NDArray[np.float64]) -> None:
        """Check each function's complex step against the finite difference at x.

        A function whose re-bound copy fails on complex numbers, changes the real value, or
        whose complex-step Jacobian differs from :func:`scipy.differentiate.jacobian`'s by
        more than its error estimate allows, is differentiated by the finite difference
        from then on.  Called at the operating point before the Jacobians are taken.
        """
        x = np.asarray(x, dtype=np.float64)
        key = (x.tobytes(), np.asarray(p, dtype=np.float64).tobytes())
        if key in self._verified:
            return
        self._verified.add(key)
        for name in self.functions:
            if self.method[name] != "complex step":
                continue
            reason = ""
            try:
                value = self._real(name, x, p)
                cfn = self.complex[name]
                if cfn is None:
                    raise TypeError("no Python code")
                cval = _call_complex(cfn, x.astype(np.complex128), p)
                if not np.allclose(cval.reshape(-1).real, value, rtol=1e-12, atol=1e-300):
                    raise ValueError("the re-bound function changes the value")
                j_cs = self.complex_jacobian(name, x, p)
                res = self._fd_result(name, x, p)
                j_fd = np.asarray(res.df, dtype=np.float64).reshape(j_cs.shape)
                err = np.asarray(res.error, dtype=np.float64).reshape(j_cs.shape)
                scale = max(1.0, float(np.max(np.abs(j_fd), initial=0.0)))
                tol = 100.0 * np.nan_to_num(err, nan=0.0) + 1e-6 * scale
                if not np.all(np.abs(j_cs - j_fd) <= tol):
                    raise ValueError(
                        f"complex step and finite difference disagree by "
                        f"{float(np.max(np.abs(j_cs - j_fd))):.3g}"
                    )
            except (ValueError, ArithmeticError, *COMPLEX_FAILURES) as exc:
                reason = f"{type(exc).__name__}: {exc}"
            if reason:
                self._fall_back(name, reason)

    @property
    def exact(self) -> bool:
        """Whether every plant function is differentiated by the complex step."""
        return all(m == "complex step" for m in self.method.values())
