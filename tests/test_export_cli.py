"""``aiofl export`` on bad input and bad designs: exit 2 with one message naming the option
or the reason and nothing written; warnings for a design that degrades sampled at Ts and
for float that does not hold; ``--params-only`` and ``--prefix`` through the CLI."""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

from aiofl.cli.app import app
from aiofl.cli.export_command import FORMATS
from aiofl.config import preset_text
from aiofl.export.c_check import CC
from aiofl.export.c_text import c_prefix

needs_cc = pytest.mark.skipif(CC is None, reason="no C compiler on PATH")


def _run(args: list[str]):
    return CliRunner().invoke(app, ["export", *args])


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["--prefix", "9motor"], "--prefix"),
        (["--prefix", "mo-tor"], "--prefix"),
        (["--prefix", "int"], "--prefix"),
        (["--prefix", "_motor"], "--prefix"),
        (["--prefix", "motor__x"], "--prefix"),
        (["--prefix", "errno"], "--prefix"),  # ERRNO_...: <errno.h>'s E[A-Z]
        (["--prefix", "string"], "--prefix"),  # str + lower case: <string.h>
        (["--prefix", "m" * 32], "--prefix"),
        (["--ts", "0"], "--ts"),
        (["--ts", "-1e-3"], "--ts"),
        (["--ts", "1.5e-4"], "--ts = 0.00015: "),
        (["--ts", "1.5e-4"], "is not an integer multiple of the step dt = 0.0001 s"),
        (["--ts", "1e-3", "--format", "vhdl"], "'vhdl' is not one of 'c', 'fmu'"),
        (["--ts", "1e-3", "--precision", "half"], "--precision"),
        ([], "no sample time"),
        (["--ts", "1e-3", "--params-only", "--params-name", "2x"], "--params-name"),
        (["--ts", "1e-3", "--params-only", "--params-name", "default_params"], "--params-name"),
        (["--ts", "1e-3", "--params-only", "--params-name", "controller"], "--params-name"),
    ],
)
def test_bad_options_exit_2_naming_the_option(tmp_path, args, needle):
    out = tmp_path / "x"
    res = _run(
        [
            "retuned-s1-leso",
            *(["--ts", "1e-3"] if args[:1] == ["--prefix"] else []),
            *args,
            "--out",
            str(out),
        ]
    )
    assert res.exit_code == 2, res.output
    assert needle in res.output
    assert not out.exists() and list(tmp_path.iterdir()) == []


def test_an_output_path_that_is_a_file_is_refused(tmp_path):
    f = tmp_path / "file"
    f.write_text("keep")
    res = _run(["retuned-s1-leso", "--ts", "1e-3", "--out", str(f)])
    assert res.exit_code == 2 and "--out" in res.output
    assert f.read_text() == "keep" and sorted(p.name for p in tmp_path.iterdir()) == ["file"]


def test_the_iofl_law_and_a_diverging_design_are_refused(tmp_path):
    """paper-s1-leso loses its plant in its own (continuous) simulation at 12.0 s (|y - r|
    past the default envelope; its numbers diverged at 12.4 s): refused."""
    for preset, needle in (
        ("iofl-s1", "IOFL law evaluates the plant model"),
        ("paper-s1-leso", "paper-s1-leso is lost at 12 s in its own simulation"),
    ):
        out = tmp_path / preset
        res = _run([preset, "--ts", "1e-3", "--out", str(out)])
        assert res.exit_code == 2, res.output
        assert needle in res.output and not out.exists()


def test_a_design_unstable_at_the_asked_ts_is_exported_with_warnings(tmp_path):
    """retuned-s1-inleso (the ITD unstable under Euler at 1 ms): written, exit 0, with the
    ITAE degradation and the unstable linearisation named; frontier-s1-ladrc at 0.2 ms
    (within 10 % of its continuous ITAE, stable) has no warning."""
    out = tmp_path / "c"
    res = _run(["retuned-s1-inleso", "--ts", "1e-3", "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert "more than the 10 % allowance" in res.output
    assert "linearised at its operating point is unstable" in res.output
    assert (out / "aiofl_controller.c").exists()
    res = _run(["frontier-s1-ladrc", "--ts", "2e-4", "--out", str(tmp_path / "d")])
    assert res.exit_code == 0 and "warning" not in res.output, res.output


def test_the_format_hook_lists_c_and_fmu():
    assert list(FORMATS) == ["c", "fmu"]


@needs_cc
def test_float_export_checks_that_float_holds(tmp_path, monkeypatch):
    """frontier-s1-ladrc (the issue's 8x ISU case) holds in float: no float warning.  A
    float build that does not hold (simulated: the check reports a 10 % ISU) is written
    with a warning suggesting double."""
    out = tmp_path / "f"
    res = _run(["frontier-s1-ladrc", "--ts", "1e-3", "--precision", "float", "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert "float does not hold" not in res.output and "not checked" not in res.output
    import aiofl.export.c_check as cc

    monkeypatch.setattr(cc, "FLOAT_ISU_TOL", 1e-9)  # any rounding now "does not hold"
    args = ["frontier-s1-ladrc", "--ts", "1e-3", "--precision", "float", "--out", str(out)]
    res = _run([*args, "--force"])
    assert res.exit_code == 0, res.output
    assert "float does not hold for frontier-s1-ladrc" in res.output
    assert "export with --precision double" in res.output


def test_params_only_and_prefix_through_the_cli(tmp_path):
    out = tmp_path / "p"
    res = _run(
        [
            "retuned-s1-ladrc",
            "--ts",
            "1e-3",
            "--prefix",
            "joint2",
            "--params-only",
            "--out",
            str(out),
        ]
    )
    assert res.exit_code == 0, res.output
    names = sorted(p.name for p in out.iterdir() if not p.name.startswith("."))
    assert names == ["joint2_retuned_s1_ladrc.c", "joint2_retuned_s1_ladrc.h"]
    text = (out / "joint2_retuned_s1_ladrc.c").read_text()
    assert "const joint2_params joint2_retuned_s1_ladrc = {" in text
    assert "#if !defined(JOINT2_LAYOUT) || JOINT2_LAYOUT != 0x" in text


@pytest.mark.parametrize("ok", ["motor", "Motor2", "j_1", "x", "aiofl", "ctl_left_arm"])
def test_good_prefixes_pass(ok):
    assert c_prefix(ok) == ok


def test_a_hostile_config_name_gives_a_plain_instance_name(tmp_path):
    """--params-only names the instance after the config's name, reduced to letters, digits
    and _: a name holding a comment closer, a directive and U+FB01 gives a plain identifier,
    and the code outside comments holds nothing of the rest."""
    import re

    text = preset_text("retuned-s1-ladrc")
    hostile = 'name = "9 x */ #define aiofl_step EVIL /* \\ufb01"'
    cfg = tmp_path / "h.toml"
    cfg.write_text(re.sub(r'^name = ".*"$', lambda _: hostile, text, count=1, flags=re.M))
    out = tmp_path / "p"
    res = _run([str(cfg), "--ts", "1e-3", "--params-only", "--out", str(out)])
    assert res.exit_code == 0, res.output
    names = sorted(p.name for p in out.iterdir() if not p.name.startswith("."))
    assert names == ["aiofl_design_9_x_define_aiofl.c", "aiofl_design_9_x_define_aiofl.h"]
    for p in out.glob("aiofl_*"):
        code = re.sub(r"/\*.*?\*/", "", p.read_text(), flags=re.S)
        assert "EVIL" not in code and "#define aiofl_step" not in code
