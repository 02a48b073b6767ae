"""A config cannot put code into the exported C.

Hostile strings (comment closers and openers, newlines and CRs, ``#``, trigraphs, line
splices, bidirectional controls, NUL, non-ASCII, 10^5 characters) go through every field
that reaches the generated files: the design's ``title`` and ``notes`` and the controller's
``structure`` label (Python API), and the config's ``name``, ``description`` and path
(``aiofl export``).  For each: the code outside comments is the code of a benign export,
character for character (Python), and with gcc (``-std=c99 -Wall -Wextra -Werror
-pedantic``, with and without ``-trigraphs``) the file compiles, its preprocessed token
stream equals the benign export's and the objects define exactly the API
(``aiofl_init/start/reset/step``, ``aiofl_default_params``; ``nm``), never
``AIOFL_INJECTED``.  Before the fix a config's ``name`` could
``#define aiofl_step`` away, add an ``#include`` or a definition, and a ``/*``, a trigraph
or a U+202E broke ``-Werror``.
"""

from __future__ import annotations

import dataclasses
import json
import re
import shutil
import string
import subprocess
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from aiofl.cli.app import app
from aiofl.controller import Controller
from aiofl.engine.discrete_rows import Sampling
from aiofl.export import HEADER, export_c

GCC = shutil.which("gcc")
NM = shutil.which("nm")
needs_gcc = pytest.mark.skipif(GCC is None or NM is None, reason="no gcc or nm on PATH")
WARN = ["-Wall", "-Wextra", "-Werror", "-pedantic"]
# ISO C99 mode already replaces trigraphs; -trigraphs says so explicitly as well
FLAGS = {"c99": ["-std=c99", *WARN], "c99-trigraphs": ["-std=c99", "-trigraphs", *WARN]}
TOKEN = "AIOFL_INJECTED"
DEFINE = f"#define aiofl_step {TOKEN}"

HOSTILE: dict[str, str] = {
    "define": f"x */ {DEFINE} /*",
    "include": "x */ #include <stdio.h> /* y",
    "definition": f"x */ int {TOKEN} = 1; /* y",
    "closer-first": f"*/ int {TOKEN} = 1; /*",
    "nested-comment": "nested /* comment",
    "newline": f"x\n{DEFINE}\n",
    "cr": f"x\r{DEFINE}\r",
    "crlf": f"x */\r\n{DEFINE}\r\n/*",
    "line-comment": f"x */ // {DEFINE}\n int {TOKEN} = 1; /*",
    "hash": f"# define {TOKEN} 1",
    "trigraph": "trigraph ??/",
    "trigraph-splice": f"x *??/\n/ int {TOKEN} = 1; /* y",
    "trigraph-hash": f"??= define {TOKEN} 1 ??( ??) ??< ??> ??! ??' ??-",
    "splice": f"x *\\\n/ int {TOKEN} = 1; /* y",
    "trailing-backslash": "trailing \\",
    "backslashes": "a\\b\\\\c\\n\\x41\\u0041",
    "bidi": f"x \u202e */ int {TOKEN} = 1; /* \u202c \u2066 y \u2069",
    "line-separator": f"x\u2028{DEFINE}\u2029\u0085",
    "nul": f"a\x00b */\x00 int {TOKEN}; /*\x00",
    "controls": "".join(chr(i) for i in range(32)) + "\x7f",
    "non-ascii": "Régler × ≤ 制御 Ω \U0001f916",
    "fullwidth": f"x \uff0a\uff0f int {TOKEN} = 1; \uff0f\uff0a",
    "quotes": '"x */ int y; " \' "',
    "long": "A" * 100_000,
    "long-hostile": f"*/ int {TOKEN} = 1; /*\n" * 4_000,
    "empty": "",
}
IDS = list(HOSTILE)


def _controller() -> Controller:
    """A LESO with Han's TD, a nonlinear SEF and a delay: most of the generator's code."""
    vals = {"law.b0": 4.0, "law.u_max": 10.0, "eso.omega0": 60.0, "td.R": 50.0}
    for i, (k, a) in enumerate(((56.0, 0.8), (15.0, 0.9)), start=1):
        vals |= {f"sef.k{i}": k / 4.0, f"sef.alpha{i}": a, f"sef.delta{i}": 0.05}
    kinds = {"eso": "linear", "td": "han", "sef": "nonlinear", "law": "aiofl"}
    ctrl = Controller(**kinds, rho=2, n_feedback=2, values=vals, structure="LESO")
    return ctrl.with_binomial_alphas()


def _refused(text: str) -> bool:
    """Whether the entry rule refuses ``text`` as a label (:func:`aiofl.text.check_text`):
    then it never reaches the export through a Controller."""
    from aiofl.text import check_text

    try:
        check_text("label", text)
    except ValueError:
        return True
    return False


CTRL = _controller()
SAMPLING = Sampling(1e-3, delay=1)


def _export(title: str = "benign", note: str = "benign note", structure: str = "LESO") -> dict:
    ctrl = dataclasses.replace(CTRL, structure=structure)
    return export_c(ctrl, SAMPLING, title=title, notes=["Config: benign.toml", note])


def _code(text: str) -> str:
    """The text outside block comments, after checking that a C compiler and this regex
    agree on where comments are (no splice, no trigraph, printable ASCII only)."""
    bad = sorted({c for c in text if not (c == "\n" or " " <= c <= "~")})
    assert not bad, f"characters that are not printable ASCII: {bad!r}"
    assert "\\" not in text and "??" not in text
    return re.sub(r"/\*.*?\*/", " ", text, flags=re.S)


def _comments(text: str) -> list[str]:
    return re.findall(r"/\*(.*?)\*/", text, flags=re.S)


BENIGN = _export()
BENIGN_CODE = {name: _code(text) for name, text in BENIGN.items()}


# ------------------------------------------------------------------ Python: every field
@pytest.mark.parametrize("field", ["title", "note", "structure"])
@pytest.mark.parametrize("hostile", HOSTILE.values(), ids=IDS)
def test_hostile_text_in_any_field_leaves_the_code_unchanged(field: str, hostile: str) -> None:
    if field == "structure" and _refused(hostile):  # a Controller's label enters checked
        with pytest.raises(ValueError, match=r"controller\.structure = "):
            _export(structure=hostile)
        return
    files = _export(**{field: hostile})
    for name, text in files.items():
        assert _code(text) == BENIGN_CODE[name], name
        for body in _comments(text):
            assert "/*" not in body  # -Wcomment: fails -Werror
        longest = max(len(line) for line in BENIGN[name].splitlines())
        assert max(len(line) for line in text.splitlines()) <= max(longest, 100)
        assert len(text) < len(BENIGN[name]) + 1_000  # 10^5 characters are cut
    if field != "structure" and hostile.startswith("A" * 50):  # the text is still there
        assert "A" * 50 in files[HEADER] and "..." in files[HEADER]


# ------------------------------------------------------------------ gcc: all fields at once
def _gcc(args: list[str], cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([str(GCC), *args], cwd=cwd, capture_output=True, text=True, check=False)


def _build(files: dict[str, str], where: Path, flags: list[str]) -> tuple[str, str]:
    """Write and compile the files (every ``.c``): (whitespace-normalised preprocessed
    sources, nm output of the objects)."""
    where.mkdir(parents=True, exist_ok=True)
    for name, text in files.items():
        (where / name).write_text(text, encoding="utf-8")
    pres, nms = [], []
    for src in sorted(n for n in files if n.endswith(".c")):
        pre = _gcc([*flags, "-E", "-P", src], where)
        assert pre.returncode == 0, pre.stderr
        obj = _gcc([*flags, "-c", "-o", src + ".o", src], where)
        assert obj.returncode == 0, obj.stderr
        nm = subprocess.run([str(NM), src + ".o"], cwd=where, capture_output=True, text=True)
        pres.append(" ".join(pre.stdout.split()))
        nms.append(nm.stdout)
    return "\n".join(pres), "".join(nms)


def _assert_clean_object(nm: str, pre: str) -> None:
    defined = {ln.split()[-1] for ln in nm.splitlines() if re.match(r"^\S+ [A-Z] ", ln)}
    api = {"aiofl_init", "aiofl_start", "aiofl_reset", "aiofl_step", "aiofl_default_params"}
    api.add("aiofl_fault")  # the fault flag of the non-finite-input policy (issue 34)
    api.add("aiofl_start_at")  # a start that takes over a held command (eso.u0, issue 33)
    assert defined == api, nm  # global definitions only
    assert TOKEN not in nm and TOKEN not in pre


@pytest.fixture(scope="module")
def benign_builds(tmp_path_factory: pytest.TempPathFactory) -> dict[str, str]:
    """The benign export's preprocessed source per flag set."""
    root = tmp_path_factory.mktemp("benign")
    out = {}
    for key, flags in FLAGS.items():
        pre, nm = _build(BENIGN, root / key, flags)
        _assert_clean_object(nm, pre)
        out[key] = pre
    return out


@needs_gcc
@pytest.mark.parametrize("hostile", HOSTILE.values(), ids=IDS)
def test_hostile_text_compiles_to_the_benign_object(
    tmp_path: Path, benign_builds: dict[str, str], hostile: str
) -> None:
    files = _export(title=hostile, note=hostile, structure="LESO" if _refused(hostile) else hostile)
    for key, flags in FLAGS.items():
        pre, nm = _build(files, tmp_path / key, flags)
        _assert_clean_object(nm, pre)
        assert pre == benign_builds[key]  # the compiler sees the benign code


# ------------------------------------------------------------------ the command line
TANK = """\
name = {name}
description = {description}
plant = "tank"

[scenario]
t_final = 1.0

[simulation]
dt = 1e-4

[controller]
structure = "LADRC"
td_kind = "exact"
rho = 1

[controller.eso]
omega0 = 20.0

[controller.sef]
omega_c = 4.0

[controller.law]
b0 = 0.05

[controller.discrete]
ts = 1e-3
"""


def _cli_export(path: Path, name: str, description: str, out: Path) -> dict[str, str]:
    """``aiofl export PATH`` of a tank LADRC config with this name and description."""
    path.parent.mkdir(parents=True, exist_ok=True)
    # JSON's escapes (\\n, \\r, \\u0000, \\u202e, ...) are TOML's
    text = TANK.format(name=json.dumps(name), description=json.dumps(description))
    path.write_text(text, encoding="utf-8")
    res = CliRunner().invoke(app, ["export", str(path), "--out", str(out)])
    assert res.exit_code == 0, res.output
    return {
        p.name: p.read_text(encoding="utf-8") for p in out.iterdir() if p.suffix in (".c", ".h")
    }


@needs_gcc
def test_cli_export_of_a_hostile_config_in_a_hostile_folder(tmp_path: Path) -> None:
    """The config's name, description and path (printed into the comment block) are each
    an injection attempt; the folder names hold ``*/``, a newline, ``#define``, ``\\``, a
    trigraph and U+202E (a file name can hold anything but ``/`` and NUL)."""
    benign = _cli_export(tmp_path / "ok" / "c.toml", "tank", "a tank", tmp_path / "out-ok")
    folder = tmp_path / "x*" / f"\n{DEFINE}\n" / "?" / "?" / "\u202e\\" / "*"
    # the path reads ".../x*/\n#define aiofl_step AIOFL_INJECTED\n/?/?/\u202e\\/*/c.toml"
    hostile = _cli_export(
        folder / "c.toml",
        f"x */ {DEFINE} /*",
        f"x */ int {TOKEN} = 1; /* y ??/ #include <stdio.h> \ufb01 \\",
        tmp_path / "out-bad",
    )
    for key, flags in FLAGS.items():
        pre_ok, nm_ok = _build(benign, tmp_path / "ok" / key, flags)
        pre, nm = _build(hostile, tmp_path / "bad" / key, flags)
        _assert_clean_object(nm, pre)
        assert pre == pre_ok and nm == nm_ok
    assert "x _/ _define aiofl_step AIOFL_INJECTED /_" in hostile[HEADER]  # inert, still legible
    # newlines, CR, NUL and U+202E are refused where they enter (aiofl.text), naming the field
    path = folder / "d.toml"
    text = TANK.format(name='"tank"', description=json.dumps("y\n??/\n#x\r\u202e\x00"))
    path.write_text(text, encoding="utf-8")
    res = CliRunner().invoke(app, ["export", str(path), "--out", str(tmp_path / "out-refused")])
    assert res.exit_code == 2 and "description = " in res.output and "U+000A" in res.output


# ------------------------------------------------------------------ the pieces
@settings(max_examples=300, deadline=None, derandomize=True)
@given(text=st.text(), limit=st.integers(4, 300))
def test_comment_text_keeps_only_inert_characters(text: str, limit: int) -> None:
    from aiofl.export.c_text import COMMENT_CHARS, comment_text

    out = comment_text(text, limit=limit)
    assert set(out) <= COMMENT_CHARS and not set(out) & set("*?\\#\n\r\x00")
    assert len(out) <= limit and out == out.strip() and "  " not in out
    assert comment_text(out, limit=limit) == out  # idempotent
    plain = "".join(c for c in text if c in string.ascii_letters + string.digits)
    if len(text) <= limit and plain:  # nothing cut: every letter and digit kept in order
        assert "".join(c for c in out if c.isalnum()) == plain


def test_c_identifier_accepts_c_names_only() -> None:
    from aiofl.export.c_text import c_identifier

    for name in ("B0", "ESO_DPHI", "x", "a" * 63):
        assert c_identifier(name) == name
    for name in ("", "0x", "_x", "__x", "a b", "a-b", "int", "static", "a" * 64, "é", f"{TOKEN}*/"):
        with pytest.raises(ValueError, match="not a C identifier"):
            c_identifier(name)


@pytest.mark.parametrize(
    ("code", "rule"),
    [
        ("/* a /* b */\nint x;\n", "'/\\*' inside a comment"),
        ("/* a */ b */\n", "'\\*/' outside a comment"),
        ("int x; // c\n", "'//' outside a comment"),
        ("/* a \\\n */\n", "a backslash"),
        ("/* ??/ */\n", "trigraph"),
        ("/* open\n", "not closed"),
        ("/* \u202e */\n", "not printable ASCII"),
        ("/* a\r */\n", "not printable ASCII"),
    ],
)
def test_the_backstop_refuses_code_that_is_not_inert(code: str, rule: str) -> None:
    from aiofl.export.c_text import check_inert

    assert check_inert("/* ok */\nint x; /* y */\n", "f.c").startswith("/* ok */")
    with pytest.raises(RuntimeError, match=rule):
        check_inert(code, "f.c")


@pytest.mark.parametrize("key", ["define", "trigraph", "splice", "bidi", "nested-comment"])
def test_export_checks_its_output_even_if_the_sanitiser_fails(monkeypatch, key: str) -> None:
    """Second layer: with comment_text replaced by the identity, a hostile title is caught
    by the backstop checks before any file is returned."""
    import aiofl.export.c_code as c_code

    monkeypatch.setattr(c_code, "comment_text", lambda text, limit=200: str(text))
    with pytest.raises(RuntimeError, match="inert-text check"):
        export_c(CTRL, SAMPLING, title=HOSTILE[key])


@pytest.mark.parametrize(
    "line", ["a */ b", "a /* b", "a \\", "a ??/", "a\nb", "a\rb", "\u202e", "a\x00"]
)
def test_a_comment_line_with_a_delimiter_is_refused(line: str) -> None:
    from aiofl.export.c_text import check_comment_line

    assert check_comment_line("plain (text) r^(rho) = r', 1/2") == "plain (text) r^(rho) = r', 1/2"
    with pytest.raises(RuntimeError, match="inert-text check"):
        check_comment_line(line)
