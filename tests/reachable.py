"""What compiled code can run from a namespace: the walk the engine's cache tests share."""

from __future__ import annotations

import types
from typing import Any


def reachable_compiled(*spaces: dict[str, Any]) -> list[Any]:
    """Every numba dispatcher and intrinsic a function compiled with the globals ``spaces``
    can call: those in the spaces, in the aiofl modules they name and, transitively, in the
    globals of those dispatchers (a plain Python function cannot be called from compiled
    code, so it is not followed)."""
    from numba.core.dispatcher import Dispatcher
    from numba.core.extending import _Intrinsic

    seen: dict[int, Any] = {}
    todo, done = list(spaces), set()
    while todo:
        space = todo.pop()
        if id(space) in done:
            continue
        done.add(id(space))
        for obj in list(space.values()):
            if isinstance(obj, types.ModuleType) and obj.__name__.startswith("aiofl."):
                todo.append(vars(obj))
            elif isinstance(obj, (Dispatcher, _Intrinsic)) and id(obj) not in seen:
                seen[id(obj)] = obj
                if isinstance(obj, Dispatcher):
                    todo.append(obj.py_func.__globals__)
    return list(seen.values())
