"""User text: one rule where it enters, one escape per format where it leaves.

Every string a user gives aiofl that can reach an output (a config's ``name``,
``description`` and ``plant``, ``[scenario] name``, a plant file's or a Python
:class:`~aiofl.plants.base.Plant`'s name, description, units, state labels, state and
parameter names, a :class:`~aiofl.Design`'s labels, a controller's ``structure`` label) is
checked once, where it enters, by :func:`check_text`, or by :func:`check_name` for a name a
model is written in; the check raises ``ValueError`` naming the field, as a bad number does
(:mod:`aiofl.checks`)::

    name = 'pe\\x00nd': U+0000 (a control character) at position 2; allowed: text without
    control characters (U+0000-U+001F, U+007F-U+009F), line or paragraph separators,
    bidirectional controls, surrogates or noncharacters, at most 200 characters

**Refused everywhere** (:func:`refused_character`): control characters (category Cc: NUL,
tab, newline, ESC, ...), line and paragraph separators (U+2028, U+2029), lone surrogates
(Cs), the noncharacters (U+FDD0-U+FDEF and the last two code points of every plane,
U+FFFE, U+FFFF, ...) and the bidirectional controls (U+061C, U+200E, U+200F,
U+202A-U+202E, U+2066-U+2069: "Trojan Source").  None of them has a use in a label or a unit,
and each breaks at least one output: XML 1.0 cannot hold a control character or a
noncharacter at all (an FMU whose ``modelDescription.xml`` no tool loads), a newline splits
a CSV row, ESC drives the terminal, NUL ends a C string and a path, a lone surrogate cannot
be encoded in UTF-8, a bidirectional control shows a reader text in another order than a
program reads it.  Everything else, any script, symbol or emoji, is kept as given.

**Names** (:func:`check_name`: states, parameters) are normalised to Unicode NFKC, the
form Python itself gives identifiers in source code (PEP 3131, so an expression
``"-ﬁ*theta"`` reads the name ``fi``): a name is what it reads as, wherever it is read
(declared, in an expression, as a ``plant_overrides`` key or an ``[uncertainty]`` parameter),
and two names that are equal after normalisation are refused naming both
(:func:`check_distinct`).

**Bounds**: at most :data:`MAX_NAME_CHARS` characters in a name, :data:`MAX_UNIT_CHARS` in a
unit, :data:`MAX_LABEL_CHARS` in a label, :data:`MAX_DESCRIPTION_CHARS` in a description and
:data:`MAX_PATH_CHARS` in a path.

**Sinks** escape for their own format all the same, as a second line that holds for text the
entry checks never saw (a file path, a message): :func:`terminal_text` (rich markup and
control sequences), :func:`xml_text` (what XML 1.0 cannot hold), :func:`one_line` (a CSV
comment line); the C export keeps only inert characters (:mod:`aiofl.export.c_text`), JSON
escapes with :func:`json.dumps` and the HTML report with :func:`html.escape`.
"""

from __future__ import annotations

import keyword
import re
import unicodedata
from collections.abc import Iterable, Mapping
from typing import Any

__all__ = [
    "MAX_DESCRIPTION_CHARS",
    "MAX_LABEL_CHARS",
    "MAX_NAME_CHARS",
    "MAX_PATH_CHARS",
    "MAX_UNIT_CHARS",
    "check_distinct",
    "check_name",
    "check_text",
    "normal_keys",
    "normal_name",
    "one_line",
    "refused_character",
    "terminal_text",
    "xml_text",
]

MAX_NAME_CHARS = 64
"""Most characters of a state or parameter name."""
MAX_UNIT_CHARS = 32
"""Most characters of a unit (``output_unit``, ``"rad/s"``)."""
MAX_LABEL_CHARS = 200
"""Most characters of a label: a config's, scenario's or plant's name, a state label."""
MAX_DESCRIPTION_CHARS = 2000
"""Most characters of a description (the shipped ones have at most 130)."""
MAX_PATH_CHARS = 4096
"""Most characters of a path given as text (``plant = "file.toml"``): Linux's PATH_MAX."""

#: the bidirectional formatting characters (Unicode's Bidi_Control property)
_BIDI_CONTROLS = frozenset(
    "\u061c\u200e\u200f\u202a\u202b\u202c\u202d\u202e\u2066\u2067\u2068\u2069"
)

_ALLOWED = (
    "text without control characters (U+0000-U+001F, U+007F-U+009F), line or paragraph "
    "separators, bidirectional controls, surrogates or noncharacters"
)


def _is_noncharacter(cp: int) -> bool:
    return 0xFDD0 <= cp <= 0xFDEF or (cp & 0xFFFE) == 0xFFFE


def _kind(ch: str) -> str | None:
    """Why ``ch`` is refused in user text (``"a control character"``), or None."""
    cat = unicodedata.category(ch)
    if cat == "Cc":
        return "a control character"
    if cat == "Cs":
        return "a lone surrogate"
    if cat in ("Zl", "Zp"):
        return "a line or paragraph separator"
    if ch in _BIDI_CONTROLS:
        return "a bidirectional control"
    if _is_noncharacter(ord(ch)):
        return "a noncharacter"
    return None


def refused_character(text: str) -> tuple[int, str, str] | None:
    """The first character of ``text`` the entry rule refuses: ``(position, "U+001B",
    why)``; None when every character is allowed."""
    for pos, ch in enumerate(text):
        why = _kind(ch)
        if why is not None:
            return pos, f"U+{ord(ch):04X}", why
    return None


def _shown(value: str) -> str:
    """``value`` for a message: its repr (which escapes every character refused here), cut."""
    return repr(value if len(value) <= 60 else value[:60] + "…")


def check_text(field: str, value: Any, *, max_chars: int = MAX_LABEL_CHARS) -> str:
    """``value`` if it is a string of allowed characters (:func:`refused_character`) and at
    most ``max_chars`` characters; else ``ValueError`` naming ``field``, the first refused
    character and its position.  The text is returned unchanged (free text is not
    normalised: a unit ``"m/s²"`` keeps its ``²``).

    Parameters
    ----------
    field
        The field, for the message.
    value
        The text.
    max_chars
        The most characters allowed (default :data:`MAX_LABEL_CHARS`).

    Returns
    -------
    str
    """
    allowed = f"{_ALLOWED}, at most {max_chars} characters"
    if not isinstance(value, str):
        raise ValueError(f"{field} = {value!r:.80}; allowed: a string ({allowed})")
    if len(value) > max_chars:
        raise ValueError(
            f"{field} = {_shown(value)} has {len(value)} characters; allowed: {allowed}"
        )
    bad = refused_character(value)
    if bad is not None:
        pos, code, why = bad
        raise ValueError(
            f"{field} = {_shown(value)}: {code} ({why}) at position {pos}; allowed: {allowed}"
        )
    return value


def normal_name(name: str) -> str:
    """``name`` in Unicode NFKC, the form Python gives identifiers (``"ﬁ"`` -> ``"fi"``)."""
    return unicodedata.normalize("NFKC", name)


def check_name(
    field: str, value: Any, *, identifier: bool = False, max_chars: int = MAX_NAME_CHARS
) -> str:
    """A state or parameter name, checked by :func:`check_text` and returned in NFKC
    (:func:`normal_name`); not empty, at most ``max_chars`` characters once normalised.
    With ``identifier`` it must also be a Python identifier not starting with ``_`` (the
    names a plant file's expressions are written in).

    Parameters
    ----------
    field, value, max_chars
        As for :func:`check_text` (default :data:`MAX_NAME_CHARS`).
    identifier
        Require a Python identifier not starting with ``_``.

    Returns
    -------
    str
        The name in NFKC.
    """
    text = normal_name(check_text(field, value, max_chars=max_chars))
    if identifier:
        if (
            not value.isidentifier()  # as Python reads source: valid as written, then NFKC
            or not text.isidentifier()
            or keyword.iskeyword(text)
            or text.startswith("_")
            or len(text) > max_chars
        ):
            raise ValueError(
                f"{field} = {_shown(value)} is not a valid name; allowed: a Python identifier "
                f"(not a keyword) not starting with _, at most {max_chars} characters"
            )
    elif not text.strip() or len(text) > max_chars:
        raise ValueError(
            f"{field} = {_shown(value)}; allowed: a name of 1 to {max_chars} characters, "
            "not only spaces"
        )
    return text


def check_distinct(field: str, names: Iterable[str]) -> None:
    """``ValueError`` naming both when two of ``names`` are equal after NFKC normalisation
    (``'fi'`` and ``'ﬁ'``: an expression could not tell them apart) or equal outright."""
    seen: dict[str, str] = {}
    for name in names:
        key = normal_name(name)
        if key in seen:
            first = seen[key]
            same = "the same name twice" if first == name else "the same name once normalised"
            raise ValueError(
                f"{field}: {first!r} and {name!r} are {same} ({key!r}, Unicode NFKC, as "
                "Python reads identifiers); allowed: distinct names"
            )
        seen[key] = name


def normal_keys(field: str, mapping: Mapping[str, Any]) -> dict[str, Any]:
    """``mapping`` with its keys (parameter names: ``plant_overrides``, ``[uncertainty]``)
    checked and normalised by :func:`check_name`, refused when two are the same name
    (:func:`check_distinct`); values unchanged."""
    out: dict[str, Any] = {}
    for key in mapping:
        out[check_name(f"{field} key", key)] = mapping[key]
    if len(out) != len(mapping):
        check_distinct(field, list(mapping))
    return out


# ------------------------------------------------------------------------- sinks
_TERMINAL_ESCAPED = re.compile(
    r"[\x00-\x1f\x7f-\x9f\u2028\u2029\ud800-\udfff]|[\u061c\u200e\u200f\u202a-\u202e\u2066-\u2069]"
)


_NAMED_ESCAPES = {"\n": "\\n", "\r": "\\r", "\t": "\\t"}


def _escape(match: re.Match[str]) -> str:
    if match.group() in _NAMED_ESCAPES:
        return _NAMED_ESCAPES[match.group()]
    cp = ord(match.group())
    return f"\\x{cp:02x}" if cp < 0x100 else f"\\u{cp:04x}"


def terminal_text(text: str, *, markup: bool = False, lines: bool = False) -> str:
    """``text`` safe to print on a terminal: every control character (ESC, BEL, CR, ...),
    line separator, bidirectional control and surrogate shown as a ``\\x1b`` /
    ``\\u202e`` escape; with ``lines`` the newlines of a multi-line text are kept; with
    ``markup`` (text printed through rich with markup on) ``[`` escaped as rich requires,
    so ``[/]`` or ``[red]`` print as written.

    Parameters
    ----------
    text
        The text.
    markup
        Escape ``[`` for rich's markup.
    lines
        Keep the newlines.

    Returns
    -------
    str
    """
    if lines:
        return "\n".join(terminal_text(line, markup=markup) for line in str(text).split("\n"))
    out = _TERMINAL_ESCAPED.sub(_escape, str(text))
    if markup:
        from rich.markup import escape

        out = escape(out)
    return out


def _xml_allowed(cp: int) -> bool:
    # XML 1.0's Char production, without the noncharacters U+FFFE, U+FFFF (refused by it)
    # and the other noncharacters and C1 controls (discouraged by it, refused by some parsers)
    if cp in (0x9, 0xA, 0xD):
        return True
    if cp < 0x20 or 0x7F <= cp <= 0x9F or 0xD800 <= cp <= 0xDFFF:
        return False
    return not _is_noncharacter(cp)


def xml_text(text: str) -> str:
    """``text`` as an XML 1.0 document can hold it: every character XML cannot represent
    (C0 controls but tab, newline and CR; C1 controls; surrogates; noncharacters such as
    U+FFFE) written as a visible ``\\u0001`` escape (even ``&#1;`` is not well formed)."""
    s = str(text)
    if all(_xml_allowed(ord(c)) for c in s):
        return s
    return "".join(c if _xml_allowed(ord(c)) else _code_escape(ord(c)) for c in s)


def _code_escape(cp: int) -> str:
    """``\\u0001`` or, past the first plane, ``\\U0001fffe``."""
    return f"\\u{cp:04x}" if cp <= 0xFFFF else f"\\U{cp:08x}"


def one_line(text: str) -> str:
    """``text`` on one line of a text file (a CSV comment, a log line): every control
    character, line separator and bidirectional control shown as an escape
    (:func:`terminal_text`), so no newline or CR splits it."""
    return terminal_text(text)
