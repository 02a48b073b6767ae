"""What identifies a plant function's compiled code: its bytecode and what it reads.

A kernel inlines the plant's functions, so its disk-cache fingerprint
(:func:`aiofl.engine.build.compile.fingerprint`) must change exactly when what numba compiles from
them changes.  numba compiles a function from its **code object** and freezes the
**globals** it reads (numbers, strings, tuples, arrays) into the machine code; it calls the
functions it names.  :func:`function_fingerprint` digests exactly that:

- the code object without its file name and line numbers: bytecode, constants (nested code
  objects recursively), names, argument layout and exception table;
- for every name the code reads that the function's globals define: a number, string,
  tuple or ``None`` by value, an array by dtype, shape and bytes, a module by name (aiofl,
  numpy, numba, scipy or the standard library: the versions of numpy, numba and Python
  are in the kernel's fingerprint already; a module of the user's own, by name and the
  text of its file), a builtin function, ufunc or class of those modules by name
  (``from math import sin``), a function (plain or compiled) by its own fingerprint,
  recursively;
- closure cells and default arguments the same way;
- the name of the module it is defined in (``__main__`` for a script or a notebook): a
  kernel loaded from numba's disk cache imports it by that name.

So editing a script's controller gains, or a plant file's parameter values (which reach the
kernel at run time, as the ``p`` array), leaves the plant's kernel valid, while any edit of
the plant's code, or of a constant it reads, makes a new one.  A function defined without a
source file (a notebook cell, ``exec``) is identified the same way.  What cannot be
identified (a global of another type, a closure over an object) makes the function
unidentifiable (None): its kernel is compiled in every process, never cached.

A cached kernel reports the line numbers of the code it was compiled from (in a plant
function's run-time error): the same code moved within its file keeps its kernel.
"""

from __future__ import annotations

import builtins
import hashlib
import sys
import threading
import types
from typing import Any

import numpy as np

__all__ = ["file_digest", "function_fingerprint", "source_digest"]

_SCALARS = (bool, int, float, complex, str, bytes, type(None))
_OWN_MODULES = ("aiofl", "numpy", "numba", "math", "cmath", "scipy", "builtins")
"""Modules identified by name alone (aiofl's own code and the packages whose versions the
kernel's fingerprint records); any other module is identified by its file's text too."""


_DIGESTS: dict[str, str] = {}  # path -> digest of the text this process first read
_DIGESTS_LOCK = threading.Lock()


def file_digest(path: str) -> str:
    """The SHA-256 of ``path``'s text now."""
    with open(path, "rb") as fh:
        return hashlib.sha256(fh.read()).hexdigest()


def source_digest(path: str) -> str:
    """The SHA-256 of ``path``'s text as this process first read it (memoized, so that a
    fingerprint describes the code loaded: :func:`aiofl.engine.build.compile.sources_changed`)."""
    with _DIGESTS_LOCK:
        if path not in _DIGESTS:
            _DIGESTS[path] = file_digest(path)
        return _DIGESTS[path]


class _Unidentifiable(Exception):
    """A value the fingerprint cannot describe."""


def function_fingerprint(fn: Any) -> str | None:
    """A digest of what numba compiles from the function ``fn`` (plain or compiled) and of
    the values it reads (see the module notes), or None if it cannot be identified."""
    try:
        h = hashlib.sha256()
        _function(fn, h, set())
    except _Unidentifiable:
        return None
    return h.hexdigest()[:32]


def _function(fn: Any, h: Any, seen: set[int]) -> None:
    py = getattr(fn, "py_func", fn)
    code = getattr(py, "__code__", None)
    if not isinstance(code, types.CodeType):
        raise _Unidentifiable(fn)
    space = getattr(py, "__globals__", {})
    # the module numba imports by this name when it loads a kernel compiled from it
    h.update(f"function {space.get('__name__')}.{py.__qualname__}|".encode())
    if id(py) in seen:  # recursion: the code is digested already
        return
    seen.add(id(py))
    _code(code, h)
    names: set[str] = set()
    _names(code, names)
    for name in sorted(names):
        if name in space:
            h.update(f"global {name}=".encode())
            _value(space[name], h, seen)
        elif not hasattr(builtins, name):
            h.update(f"unbound {name}|".encode())  # an attribute, or undefined for now
    for cell in py.__closure__ or ():
        h.update(b"cell=")
        try:
            _value(cell.cell_contents, h, seen)
        except ValueError:  # an empty cell
            h.update(b"<empty>")
    for default in py.__defaults__ or ():
        h.update(b"default=")
        _value(default, h, seen)


def _code(code: types.CodeType, h: Any) -> None:
    """The code object as numba reads it, without its file name and line numbers."""
    layout = (
        code.co_argcount,
        code.co_posonlyargcount,
        code.co_kwonlyargcount,
        code.co_nlocals,
        code.co_flags,
        code.co_names,
        code.co_varnames,
        code.co_freevars,
        code.co_cellvars,
    )
    h.update(repr(layout).encode())
    h.update(code.co_code)
    h.update(getattr(code, "co_exceptiontable", b""))
    for const in code.co_consts:
        if isinstance(const, types.CodeType):
            _code(const, h)
        else:
            h.update(f"const {type(const).__name__} {_canonical(const)}|".encode())


def _names(code: types.CodeType, out: set[str]) -> None:
    out.update(code.co_names)
    for const in code.co_consts:
        if isinstance(const, types.CodeType):
            _names(const, out)


def _canonical(value: Any) -> str:
    """``repr`` of a constant, sets sorted (their order follows the string-hash seed)."""
    if isinstance(value, set | frozenset):
        return "{" + ", ".join(sorted(_canonical(v) for v in value)) + "}"
    if isinstance(value, tuple):
        return "(" + ", ".join(_canonical(v) for v in value) + ")"
    return repr(value)


def _value(value: Any, h: Any, seen: set[int]) -> None:
    if isinstance(value, _SCALARS):
        h.update(f"{type(value).__name__} {value!r}|".encode())
    elif isinstance(value, tuple):
        h.update(f"tuple {len(value)}(".encode())
        for item in value:
            _value(item, h, seen)
        h.update(b")")
    elif isinstance(value, np.ndarray):
        h.update(f"array {value.dtype.str} {value.shape}|".encode())
        h.update(np.ascontiguousarray(value).tobytes())
    elif isinstance(value, np.generic):
        h.update(f"{value.dtype.str} {value!r}|".encode())
    elif isinstance(value, types.ModuleType):
        _module(value, h)
    elif isinstance(value, types.FunctionType) or hasattr(value, "py_func"):
        _function(value, h, seen)
    elif isinstance(value, types.BuiltinFunctionType | np.ufunc | type) and _own(value):
        # math.sin, numpy's ufuncs and scalar types: by name (their versions are recorded)
        h.update(f"{type(value).__name__} {value.__module__}.{value.__name__}|".encode())
    else:
        raise _Unidentifiable(value)


def _own(value: Any) -> bool:
    """Whether a builtin, ufunc or class comes from a module identified by name alone."""
    module = getattr(value, "__module__", None) or ("numpy" if isinstance(value, np.ufunc) else "")
    return _named_only(module)


def _named_only(module: str) -> bool:
    """Whether the module ``module`` is identified by its name alone (see the module notes)."""
    root = module.split(".", 1)[0]
    return root in _OWN_MODULES or root in sys.stdlib_module_names


def _module(module: types.ModuleType, h: Any) -> None:
    name = module.__name__
    h.update(f"module {name}|".encode())
    if _named_only(name):
        return
    path = getattr(module, "__file__", None)
    if not path:
        raise _Unidentifiable(module)
    try:
        h.update(source_digest(path).encode())
    except OSError as exc:
        raise _Unidentifiable(module) from exc
