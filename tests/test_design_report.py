"""aiofl report: a page for any design, from the pieces reproduce's page is made of."""

from __future__ import annotations

import json
from html.parser import HTMLParser
from pathlib import Path

from typer.testing import CliRunner

from aiofl.cli.app import app

DATA = Path(__file__).parent / "data"


class _Tags(HTMLParser):
    def __init__(self) -> None:
        super().__init__()
        self.open: list[str] = []
        self.text: list[str] = []

    def handle_starttag(self, tag: str, attrs: object) -> None:
        if tag not in ("img", "meta", "br"):
            self.open.append(tag)

    def handle_endtag(self, tag: str) -> None:
        assert self.open and self.open[-1] == tag, (tag, self.open[-5:])
        self.open.pop()

    def handle_data(self, data: str) -> None:
        self.text.append(data)


def _page_text(path: Path) -> str:
    p = _Tags()
    p.feed(path.read_text())
    assert p.open == []  # every element closed, in order
    return " ".join(p.text)


def test_report_of_a_users_design(tmp_path):
    out = tmp_path / "rep"
    res = CliRunner().invoke(app, ["report", str(DATA / "maglev-ladrc.toml"), "-o", str(out)])
    assert res.exit_code == 0, res.output
    text = _page_text(out / "report.html")
    assert "What the plant did" in text and "ok (the plant stayed" in text
    assert "overshoot" in text and "Operating point" in text and "UNSTABLE" in text
    data = json.loads((out / "report.json").read_text())
    assert data["run"]["status"] == "ok"
    assert data["margins"]["continuous loop: verdict"] == "stable"
    assert data["operating_point"]["open_loop_unstable"] is True
    assert (out / "figure.png").read_bytes()[:4] == b"\x89PNG"
    md = (out / "report.md").read_text()  # the same sections, in Markdown
    assert md.startswith("# Design report: ") and "What the plant did" in md
    assert "Operating point" in md and "UNSTABLE" in md and "figure.png" in md
    assert data["export"] == {}  # a continuous design: no Ts to export at, said in a note
    assert any(n.startswith("export not checked: a continuous design") for n in data["notes"])
    # an existing OUT is refused without --force, as by every command
    res = CliRunner().invoke(app, ["report", str(DATA / "maglev-ladrc.toml"), "-o", str(out)])
    assert res.exit_code == 2 and "--force" in res.output


def test_report_of_a_sampled_design_with_uncertainty(tmp_path):
    out = tmp_path / "rep"
    res = CliRunner().invoke(app, ["report", "assisted-s1-ladrc", "-o", str(out), "--draws", "4"])
    assert res.exit_code == 0, res.output
    text = _page_text(out / "report.html")
    assert "(the controller unsampled: a limit)" in text
    at = "sampled loop at Ts = 0.001 s (what the processor runs)"
    assert f"{at}: spectral radius" in text and "Export check" in text
    data = json.loads((out / "report.json").read_text())
    assert data["margins"][f"{at}: spectral radius"].endswith("(stable)")
    assert float(data["margins"][f"{at}: phase margin [deg]"]) > 0
    # disk margins and the encoder's noise in u, each row labelled with what it includes
    lv = "sampled at Ts = 1 ms: ZOH + 0-sample computation delay"
    alpha = data["margins"][f"{lv}: disk margin α (gain ±dB, phase ±deg)"]
    assert 0 < float(alpha.split()[0]) < 2
    noise = data["margins"][
        f"{lv}: RMS of u from the measurement noise (ADC quantum q = 0.00153398 (q²/12))"
    ]
    assert 0 < float(noise.split()[0]) < 1 and noise.endswith("V")
    # the exported C runs the config's loop with the engine's discrete controller beside it
    agree = data["export"]["exported C (double) vs the engine's discrete controller: max |u_C - u|"]
    du, rest = agree.split(" over ")
    assert float(du) < 1e-9 and rest.startswith("20000 samples")  # 20 s at 1 ms
    assert "Robustness over the [uncertainty] draws" in text
    data = json.loads((out / "report.json").read_text())
    assert data["robustness"]["draws"] == 4
    assert sum(data["robustness"]["status_counts"].values()) == 4
    labels = [row[0] for row in data["sensors"]]
    assert labels[1].startswith("ideal sensor") and "encoder-12bit" in labels
