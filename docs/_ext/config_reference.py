"""The configuration reference, generated from the pydantic schema when the docs build.

:func:`schema_keys` walks the models of :mod:`aiofl.config.schema` (and the ``[tune]``,
``[uncertainty]`` models the schema hands those tables to), :func:`reference_rst` renders
every table and key with its type, allowed range and default read from the models, and the
meaning from :mod:`config_keys`.  A key of the schema without a meaning, or a meaning for
a key the schema does not have, stops the build (:class:`ReferenceDrift`), so the page
cannot drift from the code.  The Sphinx directive ``.. aiofl-config-reference::`` inserts
the text.
"""

from __future__ import annotations

import math
import re
import types
import typing
from dataclasses import dataclass
from typing import Annotated, Any, Literal, get_args, get_origin

import annotated_types as at
from config_keys import KEY_MEANINGS, PLANT_FILE_KEYS, TABLE_MEANINGS
from pydantic import BaseModel
from pydantic.fields import FieldInfo


class ReferenceDrift(RuntimeError):
    """The meanings and the schema disagree: a key without a meaning or a stale meaning."""


@dataclass(frozen=True)
class Key:
    """One key of the schema: its dotted path, type, range, default and required flag."""

    table: str  # "" for the top level, else e.g. "controller.eso"
    name: str
    type: str
    allowed: str
    default: str
    required: bool

    @property
    def path(self) -> str:
        return f"{self.table}.{self.name}" if self.table else self.name


def _models() -> tuple[type[BaseModel], dict[str, type[BaseModel]]]:
    """The root model and the models that validate the tables typed ``dict[str, Any]``."""
    from aiofl.config.schema import ConfigModel
    from aiofl.tuning.space import TuneSettings

    return ConfigModel, {"tune": TuneSettings}


def _dynamic_allowed() -> dict[str, str]:
    """Allowed values a validator checks against a registry, read from it."""
    from aiofl.plants.registry import available_plants
    from aiofl.rig import RIG_PRESETS
    from aiofl.sensor import SENSOR_PRESETS

    def names(xs: object) -> str:
        return " | ".join(f'``"{x}"``' for x in xs)  # type: ignore[attr-defined]

    return {
        "plant": f"{names(available_plants())} or a plant file ``*.toml``",
        "sensor.preset": names(SENSOR_PRESETS),
        "rig.sensor": names(SENSOR_PRESETS),
        "rig.preset": names(RIG_PRESETS),
    }


def _number(x: float) -> str:
    if isinstance(x, bool):
        return str(x).lower()
    if isinstance(x, int) and abs(x) >= 2**31:
        e = math.log2(x)
        return f"2^{int(e)}" if e == int(e) else f"{x:g}"
    if isinstance(x, float) and math.isinf(x):
        return "inf" if x > 0 else "-inf"
    return f"{x:g}".replace("e+", "e")


def _constraints(meta: list[Any]) -> tuple[list[str], bool]:
    """(range texts, finite) of annotated-types / pydantic metadata."""
    lo = hi = None
    out: list[str] = []
    finite = False
    for m in meta:
        if isinstance(m, FieldInfo):
            sub, fin = _constraints(list(m.metadata))
            out += sub
            finite = finite or fin
        elif isinstance(m, at.Gt):
            lo = f"> {_number(m.gt)}"
        elif isinstance(m, at.Ge):
            lo = f">= {_number(m.ge)}"
        elif isinstance(m, at.Lt):
            hi = f"< {_number(m.lt)}"
        elif isinstance(m, at.Le):
            hi = f"<= {_number(m.le)}"
        elif isinstance(m, at.MinLen):
            out.append(f"at least {m.min_length} entries")
        elif isinstance(m, at.MaxLen):
            out.append(f"at most {m.max_length} entries")
        elif type(m).__name__ == "AllowInfNan" and not m.allow_inf_nan:
            finite = True
    if "at least 2 entries" in out or any(o.startswith("at least") for o in out):
        lens = [o.split()[2] for o in out if o.startswith(("at least", "at most"))]
        if len(lens) == 2 and lens[0] == lens[1]:
            out = [o for o in out if not o.startswith(("at least", "at most"))]
            out.append(f"exactly {lens[0]} entries")
    bound = " and ".join(b for b in (lo, hi) if b)
    if bound:
        out.insert(0, bound)
    return out, finite


_SCALARS = {float: "number", int: "integer", bool: "boolean", str: "string", Any: "any"}


def _type(tp: Any) -> tuple[str, str]:
    """(type text, allowed-values text) of an annotation."""
    origin = get_origin(tp)
    if origin is Annotated:
        base, *meta = get_args(tp)
        text, allowed = _type(base)
        ranges, finite = _constraints(meta)
        parts = [p for p in (allowed, *ranges) if p]
        if finite:
            parts.append("finite")
        return text, ", ".join(parts)
    if origin in (typing.Union, types.UnionType):
        args = [a for a in get_args(tp) if a is not type(None)]
        rendered = [_type(a) for a in args]
        if len(rendered) == 1:
            return rendered[0]
        texts = [t if not a else f"{t} ({a})" for t, a in rendered]
        return " or ".join(texts), ""
    if origin is Literal:
        return "string" if all(isinstance(v, str) for v in get_args(tp)) else "value", " | ".join(
            f'``"{v}"``' if isinstance(v, str) else f"``{v}``" for v in get_args(tp)
        )
    if origin is list:
        (item,) = get_args(tp)
        text, allowed = _type(item)
        return f"list of {text}", (f"each {allowed}" if allowed else "")
    if origin is dict:
        _, item = get_args(tp)
        text, allowed = _type(item)
        return f"table of {text}", (f"each {allowed}" if allowed else "")
    if isinstance(tp, type) and issubclass(tp, BaseModel):
        return "table", ""
    return _SCALARS.get(tp, getattr(tp, "__name__", str(tp))), ""


def _default(field: FieldInfo) -> tuple[str, bool]:
    """(default text, required)."""
    if field.is_required():
        return "required", True
    factory = field.default_factory
    value = factory() if factory is not None else field.default  # type: ignore[call-arg]
    if value is None:
        return "not set", False
    if isinstance(value, BaseModel):
        return "its keys' defaults", False
    if isinstance(value, bool):
        return f"``{str(value).lower()}``", False
    if isinstance(value, str):
        return f'``"{value}"``', False
    if isinstance(value, float):
        text = repr(value) if len(repr(value)) <= 8 else f"{value:.6g}"
        return f"``{text.replace('e+', 'e')}``", False
    if isinstance(value, list | dict) and not value:
        return "empty", False
    return f"``{value!r}``", False


def _sub_model(tp: Any) -> tuple[type[BaseModel] | None, bool]:
    """(model, keyed) when the annotation is a table: a model, or a table of models keyed
    by a user's name (``[tune.parameters]``: ``"eso.omega0" = {lo, hi}``)."""
    args = (
        [a for a in get_args(tp) if a is not type(None)]
        if get_origin(tp)
        in (
            typing.Union,
            types.UnionType,
        )
        else [tp]
    )
    for a in args:
        if isinstance(a, type) and issubclass(a, BaseModel):
            return a, False
        if get_origin(a) is dict:
            item = get_args(a)[1]
            if isinstance(item, type) and issubclass(item, BaseModel):
                return item, True
    return None, False


def schema_keys() -> dict[str, list[Key]]:
    """Every table of the schema (``""`` the top level), in the schema's order, with its
    keys; a table keyed by the user's names is ``TABLE.NAME`` (``uncertainty.parameters.NAME``)."""
    root, delegated = _models()
    tables: dict[str, list[Key]] = {}
    dynamic = _dynamic_allowed()

    def walk(model: type[BaseModel], table: str) -> None:
        keys = tables.setdefault(table, [])
        for name, field in model.model_fields.items():
            path = f"{table}.{name}" if table else name
            sub, keyed = _sub_model(field.annotation)
            if sub is None and path in delegated:
                sub = delegated[path]
            text, allowed = _type(field.annotation)
            ranges, finite = _constraints(list(field.metadata))
            allowed = ", ".join(p for p in (allowed, *ranges, "finite" if finite else "") if p)
            allowed = dynamic.get(path, allowed)
            default, required = _default(field)
            if sub is not None and path in delegated:
                text, default = "table", "not set"
            keys.append(Key(table, name, text, allowed, default, required))
            if sub is not None:
                walk(sub, f"{path}.NAME" if keyed else path)

    walk(root, "")
    return tables


def check_meanings(tables: dict[str, list[Key]]) -> None:
    """Raise :class:`ReferenceDrift` unless every key and table has exactly one meaning."""
    paths = {k.path for keys in tables.values() for k in keys}
    missing = sorted(paths - set(KEY_MEANINGS))
    stale = sorted(set(KEY_MEANINGS) - paths)
    missing_tables = sorted(set(tables) - set(TABLE_MEANINGS))
    stale_tables = sorted(set(TABLE_MEANINGS) - set(tables))
    problems = []
    if missing:
        problems.append(f"keys of the schema without a meaning in config_keys.py: {missing}")
    if stale:
        problems.append(f"meanings of keys the schema does not have: {stale}")
    if missing_tables:
        problems.append(f"tables without a meaning: {missing_tables}")
    if stale_tables:
        problems.append(f"meanings of tables the schema does not have: {stale_tables}")
    from aiofl.plants.symbolic import SymbolicPlant

    if set(PLANT_FILE_KEYS) != set(SymbolicPlant._KEYS):
        problems.append(
            "plant-file keys differ from SymbolicPlant._KEYS: "
            f"{sorted(set(PLANT_FILE_KEYS) ^ set(SymbolicPlant._KEYS))}"
        )
    if problems:
        raise ReferenceDrift("; ".join(problems))


def _required_by_kind() -> dict[str, str]:
    """``controller.PART.KEY`` -> the component kinds that need it given (no default is
    used for them), from :data:`aiofl.config.schema.REQUIRED_BY_KIND`."""
    from aiofl.config.schema import REQUIRED_BY_KIND

    words = {"eso": "observer", "td": "differentiator", "sef": "feedback", "law": "law"}
    kinds: dict[str, list[str]] = {}
    for (part, kind), keys in REQUIRED_BY_KIND.items():
        for key in keys:
            kinds.setdefault(f"controller.{part}.{key}", []).append(kind)
    return {
        path: f"{words[path.split('.')[1]]} is {' or '.join(f'``{k}``' for k in ks)}"
        for path, ks in kinds.items()
    }


def _escape_bars(text: str) -> str:
    """``|x|`` outside literals, escaped: reST would read it as a substitution."""
    parts = re.split(r"(``.*?``)", text)
    return "".join(p if p.startswith("``") else p.replace("|", "\\|") for p in parts)


def _anchor(table: str) -> str:
    return "config-" + (table.replace(".", "-").replace("NAME", "name") or "top")


def _heading(table: str) -> str:
    return "Top level" if not table else f"[{table}]"


def reference_rst() -> str:
    """The reference as reStructuredText: one section per table, one entry per key."""
    from aiofl.config.schema import REQUIRED_KEYS

    tables = schema_keys()
    check_meanings(tables)
    required_by = _required_by_kind()
    lines: list[str] = []
    for table, keys in tables.items():
        title = _heading(table)
        lines += [f".. _{_anchor(table)}:", "", title, "-" * max(len(title), 4), ""]
        lines += [_escape_bars(TABLE_MEANINGS[table]), ""]
        for key in keys:
            if key.type == "table":
                sub = next((t for t in tables if t in (key.path, f"{key.path}.NAME")), None)
                if sub is not None:
                    lines += [
                        f"``{key.path}``",
                        f"   table: see :ref:`{_anchor(sub)}`.  "
                        + _escape_bars(KEY_MEANINGS[key.path]),
                        "",
                    ]
                    continue
            must = " **(required in every config)**" if key.path in REQUIRED_KEYS else ""
            facts = [f"type: {key.type}"]
            if key.allowed:
                facts.append(f"allowed: {key.allowed}")
            kinds = required_by.get(key.path)
            if must:
                facts.append("default: none, must be set")
            elif kinds:
                facts.append(f"default: none, must be given when the {kinds}")
            else:
                facts.append(f"default: {key.default}")
            lines += [f"``{key.path}``{must}", "   " + "; ".join(facts) + ".", ""]
            lines += ["   " + _escape_bars(KEY_MEANINGS[key.path]), ""]
    lines += [".. _config-plant-file:", "", "Plant file", "----------", ""]
    lines += [
        'A plant file (``plant = "my_plant.toml"`` in a run config) is a TOML file of its '
        "own, read by :meth:`aiofl.plants.symbolic.SymbolicPlant.from_dict`; its keys:",
        "",
    ]
    for name, meaning in PLANT_FILE_KEYS.items():
        lines += [f"``{name}``", f"   {_escape_bars(meaning)}", ""]
    return "\n".join(lines)


def setup(app: Any) -> dict[str, Any]:
    from docutils.statemachine import StringList
    from sphinx.util.docutils import SphinxDirective

    class ConfigReference(SphinxDirective):
        has_content = False

        def run(self) -> list[Any]:
            from docutils import nodes

            container = nodes.container()
            self.state.nested_parse(
                StringList(reference_rst().splitlines(), source="aiofl.config.schema"),
                self.content_offset,
                container,
                match_titles=True,
            )
            return container.children

    app.add_directive("aiofl-config-reference", ConfigReference)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
