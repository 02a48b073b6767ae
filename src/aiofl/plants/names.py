"""The names a symbolic plant is written in, and its text, under the rule of :mod:`aiofl.text`.

A plant file's states and parameters are declared by name and used by name in its
expressions.  Python's parser, which reads the expressions
(:func:`aiofl.plants.expressions.parse_expression`), gives every identifier in Unicode NFKC
(PEP 3131): ``"-ﬁ*theta"`` reads the name ``fi``.  So a declared name is normalised the
same way (:func:`declared_symbols`), a sympy symbol given from Python is renamed to its
normal name wherever it is used (:func:`normal_symbols`, :func:`renamed`), and two names
that are one once normalised (``"fi"`` and ``"ﬁ"`` with two values) are refused naming both:
before, the expression silently used the value of the other one.

:func:`plant_text` applies a check of :mod:`aiofl.text` (the plant's name, description,
labels and units) and raises its refusal as a
:class:`~aiofl.plants.expressions.SymbolicPlantError`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import sympy as sp

from aiofl.plants.expressions import CONSTANTS, FUNCTIONS, SymbolicPlantError
from aiofl.text import check_distinct, check_name, normal_name

__all__ = ["declared_symbols", "normal_symbols", "plant_text", "renamed"]


def plant_text(check: Any, field: str, value: Any, **kwargs: Any) -> Any:
    """``check(field, value, **kwargs)`` (:func:`aiofl.text.check_text`, ...), its
    ``ValueError`` raised as a :class:`SymbolicPlantError`.

    Parameters
    ----------
    check
        A text check, ``check(field, value, **kwargs)``.
    field, value
        The field's name and value.
    **kwargs
        Passed on to ``check``.

    Returns
    -------
    object
        What ``check`` returns (the normalised text).
    """
    try:
        return check(field, value, **kwargs)
    except ValueError as exc:
        raise SymbolicPlantError(str(exc)) from None


def declared_symbols(
    plant: str, states: Sequence[Any], params: Sequence[Any]
) -> tuple[dict[str, sp.Symbol], dict[Any, str]]:
    """The symbols of a plant file's state and parameter names: ``(symbols by normal name,
    normal name by declared name)``.

    Each name must be a Python identifier not starting with ``_``
    (:func:`aiofl.text.check_name`), not a function or constant of the expressions, and
    distinct from every other once normalised.  Raises :class:`SymbolicPlantError` naming
    the name(s) at fault.

    Parameters
    ----------
    plant
        The plant's name, for messages.
    states, params
        The declared state and parameter names.

    Returns
    -------
    symbols : dict of str to sympy.Symbol
    normal : dict
    """
    symbols: dict[str, sp.Symbol] = {}
    normal: dict[Any, str] = {}
    for key, nm in [*(("states", s) for s in states), *(("params", p) for p in params)]:
        nn = plant_text(check_name, f"plant {plant!r}: {key} name", nm, identifier=True)
        if nn in FUNCTIONS or nn in CONSTANTS:
            raise SymbolicPlantError(
                f"plant {plant!r}: {key} name {nm!r} is reserved (a function or constant "
                "name of the expressions)"
            )
        normal[nm] = nn
        symbols[nn] = sp.Symbol(nn, real=True)
    plant_text(check_distinct, f"plant {plant!r}: states and params", [*states, *params])
    return symbols, normal


def normal_symbols(plant: str, states: Sequence[Any], params: Sequence[Any]) -> dict[Any, Any]:
    """The symbols among ``states`` and ``params`` whose names are not in NFKC, each mapped
    to the symbol of its normal name (same assumptions); :class:`SymbolicPlantError` when a
    name breaks the text rule or two names are one once normalised.

    Parameters
    ----------
    plant
        The plant's name, for messages.
    states, params
        The state and parameter symbols.

    Returns
    -------
    dict
    """
    names = [str(s) for s in (*states, *params)]
    for i, nm in enumerate(names, 1):
        plant_text(check_name, f"plant {plant!r}: the name of symbol {i}", nm)
    plant_text(check_distinct, f"plant {plant!r}: states and params", names)
    out = {}
    for sym in (*states, *params):
        nn = normal_name(str(sym))
        if nn != str(sym) and isinstance(sym, sp.Symbol):
            out[sym] = sp.Symbol(nn, **sym.assumptions0)
    return out


def renamed(value: Any, symbols: Mapping[Any, Any]) -> Any:
    """``value`` (an expression, a list of them, a string or None) with the symbols of
    ``symbols`` replaced; strings and None unchanged (a string is parsed with the normal
    names)."""
    if isinstance(value, (list, tuple)):
        return type(value)(renamed(e, symbols) for e in value)
    if isinstance(value, (sp.Basic, sp.MatrixBase)):
        return value.xreplace(symbols)
    return value
