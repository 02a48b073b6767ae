"""The test suite's chain of three integrators, one plant for every test that needs one.

x1''' = -a sin x1 - c x1'' + b u, y = x1: already in normal form (ξ = x,
α = -a sin x1 - c x3, β = b, ρ = 3).  With a = c = 0 it is the pure chain y''' = b u.  Tests
that need a chain take this one with their own parameters (:func:`chain3`): a kernel is
compiled per plant *code*, so one definition means one compile for all of them.
"""

from __future__ import annotations

from math import sin
from typing import Any

from aiofl.plants.base import Plant


def chain_f(x: Any, p: Any) -> tuple[float, float, float]:
    return (x[1], x[2], -p[0] * sin(x[0]) - p[1] * x[2])


def chain_g(x: Any, p: Any) -> tuple[float, float, float]:
    return (0.0, 0.0, p[2])


def chain_h(x: Any, p: Any) -> float:
    return x[0]


def chain_nf(x: Any, p: Any) -> tuple[float, float, float, float, float]:
    return (x[0], x[1], x[2], -p[0] * sin(x[0]) - p[1] * x[2], p[2])


def chain3(
    a: float, c: float, b: float, *, name: str = "chain3", normal_form: bool = True
) -> Plant:
    """The chain with parameters a, c, b (with its normal form unless ``normal_form`` is
    false: a plant that declares none)."""
    return Plant(
        name=name,
        n_states=3,
        f=chain_f,
        g=chain_g,
        h=chain_h,
        params={"a": a, "c": c, "b": b},
        relative_degree=3 if normal_form else None,
        normal_form=chain_nf if normal_form else None,
        description="x1''' = -a sin x1 - c x1'' + b u: already a chain of 3 integrators",
    )
