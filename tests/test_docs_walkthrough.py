"""The manual's walk-through and Python quickstart run as written (issues 22, 38).

The blocks live on the getting-started page (``docs/getting-started.md``); the README's
quickstart is run too.  A fenced block preceded by ``<!-- test: walkthrough -->`` is a
shell session: every line is an ``aiofl`` command (``#`` starts a comment, ``> FILE``
captures stdout) run in order in a temporary folder; each must exit 0.  To keep the test
short, the config the walk-through copies is cut to a 2-s horizon (and 4 robust-tuning
draws) right after ``aiofl show``; the commands themselves are not changed.  The block
after ``<!-- test: quickstart -->`` is run as Python.
"""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest
from typer.testing import CliRunner

from aiofl.cli.app import app

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "docs" / "getting-started.md"
README = ROOT / "README.md"


def _block(tag: str, page: Path = PAGE) -> tuple[str, str]:
    """The (language, text) of the fenced block right after ``<!-- test: TAG -->``."""
    text = page.read_text(encoding="utf-8")
    m = re.search(rf"<!-- test: {tag} -->\n```(\w+)\n(.*?)\n```", text, re.S)
    assert m is not None, f"{page.name} has no block marked <!-- test: {tag} -->"
    return m[1], m[2]


def _commands(block: str) -> list[tuple[list[str], str | None]]:
    """(arguments after ``aiofl``, stdout file or None) for every line of a shell block."""
    out = []
    for line in block.splitlines():
        line = line.split(" #", 1)[0].strip()
        if not line or line.startswith("#"):
            continue
        redirect = None
        if ">" in line:
            line, target = line.split(">", 1)
            redirect = target.strip()
        args = shlex.split(line)
        assert args[0] == "aiofl", line
        out.append((args[1:], redirect))
    return out


def _shorten(path: Path) -> None:
    """The copied preset cut to a 2-s horizon, 4 draws per robust-tuning candidate."""
    text = path.read_text(encoding="utf-8")
    assert "t_final = 20.0" in text
    text = text.replace("t_final = 20.0", "t_final = 2.0")
    text = re.sub(r"robust = \{ draws = \d+", "robust = { draws = 4", text)
    path.write_text(text, encoding="utf-8")


def test_the_walkthrough_block_is_a_session_of_aiofl_commands() -> None:
    lang, block = _block("walkthrough")
    assert lang == "bash"
    commands = _commands(block)
    names = [args[0] for args, _ in commands]
    for cmd in ("show", "simulate", "tune", "export", "robustness"):
        assert cmd in names
    show = next(args for args, _ in commands if args[0] == "show")
    assert show[1] != "paper-s1-leso"  # the walk-through starts from a design that works


def test_the_walkthrough_runs_in_order(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    runner = CliRunner()
    for args, redirect in _commands(_block("walkthrough")[1]):
        res = runner.invoke(app, args)
        assert res.exit_code == 0, (args, res.output, res.exception)
        if args[0] == "export":  # the walk-through's design does not diverge sampled
            assert "diverges" not in res.stderr and "unstable" not in res.stderr, res.stderr
        if redirect is not None:
            Path(redirect).write_text(res.stdout, encoding="utf-8")
            if args[0] == "show":
                _shorten(Path(redirect))
    assert (tmp_path / "runs" / "tuned" / "best.toml").is_file()
    assert (tmp_path / "c" / "aiofl_controller.c").is_file()


@pytest.mark.parametrize("page", [PAGE, README], ids=["getting-started", "README"])
def test_the_python_quickstart_runs(page: Path) -> None:
    lang, code = _block("quickstart", page)
    assert lang == "python" and "paper-s1-inleso" not in code
    namespace: dict[str, object] = {}
    exec(compile(code, f"{page.name} quickstart", "exec"), namespace)
    res = namespace["res"]
    assert not res.failed and res.metrics["itae"] < 0.05  # type: ignore[attr-defined]
    assert not namespace["out"].failed.any()  # type: ignore[attr-defined]


def test_the_readme_fits_on_a_screen_and_its_links_reach_pages() -> None:
    """Issue 38: the README is at most 150 lines and every page it links exists."""
    text = README.read_text(encoding="utf-8")
    assert len(text.splitlines()) <= 150
    links = re.findall(r"\]\(((?:docs|examples)/[^)#]+)\)", text)
    assert len(links) >= 15, links
    missing = [link for link in links if not (ROOT / link).is_file()]
    assert not missing, missing
