r"""Text from outside aiofl made inert before it reaches the generated C.

A config file is shared and downloaded, and the C code it produces goes into firmware, so
no text a user controls (the config's ``name`` and ``description``, its path, a
:class:`~aiofl.controller.Controller`'s ``structure`` label given through the Python API,
anything else) may reach the C files except through :func:`comment_text`, which keeps only
characters that are inert inside a C block comment and bounds the length.  The generator
(:mod:`aiofl.export.c_code`) writes that text only inside ``/* ... */`` blocks and never as
code.  Identifiers in the code are aiofl's own; :func:`c_identifier` still checks each one
the code declares.  Two backstops check the result once more: :func:`check_comment_line`
every line the generator puts into a comment (no comment delimiter, nothing that becomes
one), and :func:`check_inert` every generated file (printable ASCII only, no backslash, no
``??``, comments well formed).

What can turn comment text into code, and why it cannot happen here:

* ``*/`` ends the comment and ``/*`` inside one fails ``-Werror`` (``-Wcomment``): ``*`` is
  never kept, and ``/`` alone opens or closes nothing;
* a backslash before a line end splices the next line into the comment's last one (``*\``
  + newline + ``/`` is a comment closer), and the trigraph ``??/`` is a backslash under
  ``-trigraphs``: ``\`` and ``?`` are never kept;
* a newline or carriage return would start a new line outside the ``*`` margin, and
  ``#`` at a line start reads like a directive to a reviewer: whitespace becomes one space,
  ``#`` is never kept;
* control characters (NUL), bidirectional controls (U+202E, "Trojan Source") and any other
  non-ASCII character can hide code from a reviewer or fail a compiler: only ASCII letters,
  digits and ``space _ . , : ; = + - / ( )`` are kept.
"""

from __future__ import annotations

import re
import string

__all__ = [
    "COMMENT_CHARS",
    "MAX_COMMENT_TEXT",
    "c_identifier",
    "c_prefix",
    "check_comment_line",
    "check_inert",
    "comment_text",
]

COMMENT_CHARS = frozenset(string.ascii_letters + string.digits + " _.,:;=+-/()")
"""The characters :func:`comment_text` keeps; every other one is replaced."""

MAX_COMMENT_TEXT = 200
"""Default bound on the length of one field of user text in a comment (characters)."""

_REPLACEMENT = "_"
_ELLIPSIS = "..."

# C99's keywords (6.4.1) but _Bool, _Complex, _Imaginary: names starting with _ are refused
_C_KEYWORDS = frozenset(
    "auto break case char const continue default do double else enum extern float for goto "  # noqa: SIM905
    "if inline int long register restrict return short signed sizeof static struct switch "
    "typedef union unsigned void volatile while".split()
)
_IDENTIFIER = re.compile(r"[A-Za-z][A-Za-z0-9_]{0,62}")


def comment_text(text: str, *, limit: int = MAX_COMMENT_TEXT) -> str:
    """``text`` made inert for a C block comment: the only way user text enters the C.

    Parameters
    ----------
    text
        Any text (a config's name, description or path; a label).
    limit
        Most characters returned (at least 4); longer text is cut and ends in ``...``.

    Returns
    -------
    str
        Only characters of :data:`COMMENT_CHARS`: every run of whitespace (newline, CR,
        tab, Unicode spaces) becomes one space, every run of other characters (``*``,
        ``?``, ``\\``, ``#``, quotes, control, bidirectional and non-ASCII characters)
        one ``_``; leading and trailing spaces removed.  May be empty.  Reading stops once
        the limit is passed.

    Examples
    --------
    >>> comment_text("x */ #define aiofl_step EVIL /*")
    'x _/ _define aiofl_step EVIL /_'
    """
    if limit < len(_ELLIPSIS) + 1:
        raise ValueError(f"limit = {limit}; allowed: >= {len(_ELLIPSIS) + 1}")
    out: list[str] = []
    for ch in str(text):
        if ch.isspace() or ch not in COMMENT_CHARS:
            sub = " " if ch.isspace() else _REPLACEMENT
            if not out or out[-1] != sub:
                out.append(sub)
        else:
            out.append(ch)
        if len(out) > limit + 2:  # enough to know that it is cut
            break
    result = "".join(out).strip()
    if len(result) > limit:
        result = result[: limit - len(_ELLIPSIS)].rstrip() + _ELLIPSIS
    return result


def c_identifier(name: str) -> str:
    """``name`` if it is a C99 identifier the generated code may declare, else ValueError.

    Allowed: an ASCII letter, then letters, digits and ``_``, at most 63 characters (C99's
    guaranteed significant length), not a keyword; names starting with ``_`` are reserved
    to the implementation and refused.
    """
    if not isinstance(name, str) or not _IDENTIFIER.fullmatch(name) or name in _C_KEYWORDS:
        raise ValueError(
            f"{name!r} is not a C identifier the generated code may declare; allowed: an "
            "ASCII letter, then letters, digits and _ (at most 63), not a C keyword"
        )
    return name


# names C99 (7.26) and POSIX reserve for future library use: a prefix starting so would
# give reserved names (E + digit/upper: <errno.h> macros, is/to + lower: <ctype.h>, ...)
_RESERVED_PREFIX = re.compile(
    r"(E[0-9A-Z]|is[a-z]|to[a-z]|str[a-z]|mem[a-z]|wcs[a-z]|LC_[A-Z]|SIG[A-Z_]|PRI[a-zX]"
    r"|SCN[a-zX]|int[0-9a-z]|uint[0-9a-z]|INT[0-9]|UINT[0-9]|cr[a-z])"
)
MAX_PREFIX = 31
"""Longest ``--prefix``: its names (``PREFIX_START_BUMPLESS``, ...) stay within 63."""


def c_prefix(prefix: str) -> str:
    """``prefix`` if every name ``prefix_...`` / ``PREFIX_...`` of an export is a C99
    identifier that is not reserved, else ValueError naming ``--prefix``.

    Allowed: an ASCII letter, then letters and digits, single ``_`` between them (no
    ``__``, no trailing ``_``), at most :data:`MAX_PREFIX` characters, not a C keyword and
    not starting like a reserved name (``E`` + digit or capital in upper case, ``is``,
    ``to``, ``str``, ``mem``, ``wcs`` + lower case, ...).
    """
    ok = (
        isinstance(prefix, str)
        and re.fullmatch(r"[A-Za-z][A-Za-z0-9]*(?:_[A-Za-z0-9]+)*", prefix) is not None
        and len(prefix) <= MAX_PREFIX
        and prefix not in _C_KEYWORDS
        and prefix.lower() not in _C_KEYWORDS
    )
    if not ok:
        raise ValueError(
            f"--prefix = {str(prefix)[:80]!r} is not a C identifier prefix; allowed: an ASCII "
            f"letter, then letters, digits and single _ (at most {MAX_PREFIX}), not a C keyword"
        )
    for name in (prefix + "_", prefix.upper() + "_"):
        if _RESERVED_PREFIX.match(name):
            raise ValueError(
                f"--prefix = {prefix!r} gives names C reserves for the library ({name}...): "
                "choose another prefix"
            )
    return prefix


def _internal_error(what: str, pos: int, rule: str) -> RuntimeError:
    return RuntimeError(
        f"internal error: {what} failed the inert-text check at offset {pos} ({rule}); "
        "please report this as a bug"
    )


def _printable_ascii(text: str, what: str, *, newline: bool) -> None:
    for pos, ch in enumerate(text):
        if not ((newline and ch == "\n") or " " <= ch <= "~"):
            raise _internal_error(what, pos, f"character {ch!r} is not printable ASCII")
    for token, rule in (("\\", "a backslash"), ("??", "a trigraph '??'")):
        if token in text:
            raise _internal_error(what, text.index(token), rule)


def check_comment_line(line: str) -> str:
    """``line`` if it may stand inside a generated C block comment, else RuntimeError.

    The backstop for text the generator puts into a comment (user text arrives there made
    inert by :func:`comment_text`): one line of printable ASCII, with no ``*/`` (which would
    end the comment early and turn the rest into code), no ``/*``, no backslash and no
    ``??`` (which can become one).  A failure is a bug in aiofl.
    """
    what = f"the comment line {line[:60]!r}"
    _printable_ascii(line, what, newline=False)
    for token in ("*/", "/*"):
        if token in line:
            raise _internal_error(what, line.index(token), f"{token!r} in a comment")
    return line


def check_inert(code: str, file_name: str) -> str:
    """``code`` if a generated C file passes the backstop check, else RuntimeError.

    Checks: only printable ASCII and newlines; no backslash (line splice) and no ``??``
    (trigraph); outside comments no ``*/`` and no ``//``; inside a comment no ``/*``; every
    comment closed.  Under these rules the C compiler sees comments exactly where this
    scan does.  A failure is a bug in aiofl (user text is made inert before it gets here),
    so it is a RuntimeError naming the file, the offset and the rule.
    """
    what = f"generated {file_name}"

    def fail(pos: int, rule: str) -> RuntimeError:
        return _internal_error(what, pos, rule)

    _printable_ascii(code, what, newline=True)
    pos = 0
    while True:
        start = code.find("/*", pos)
        segment = code[pos:] if start < 0 else code[pos:start]
        for token in ("*/", "//"):
            if token in segment:
                raise fail(pos + segment.index(token), f"{token!r} outside a comment")
        if start < 0:
            return code
        end = code.find("*/", start + 2)
        if end < 0:
            raise fail(start, "a comment that is not closed")
        inner = code.find("/*", start + 2, end)
        if inner >= 0:
            raise fail(inner, "'/*' inside a comment")
        pos = end + 2
