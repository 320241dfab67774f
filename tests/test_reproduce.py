"""`jaxunilat reproduce --quick`: every figure, the summary tables and one line per claim."""

import os

import pytest

from jaxunilat._cli._main import main
from jaxunilat.paper._reproduce import FIGURES


@pytest.mark.slow
def test_reproduce_quick(tmp_path, capsys):
    out = tmp_path / "repro"
    assert main(["reproduce", "--out", str(out), "--quick"]) == 0
    text = capsys.readouterr().out
    for name in FIGURES:
        path = out / name
        assert path.is_file() and os.path.getsize(path) > 10_000, name
        with open(path, "rb") as f:
            assert f.read(8) == b"\x89PNG\r\n\x1a\n"
    summary = (out / "summary.md").read_text()
    assert "## Table 1" in summary and "## Table 2: the coupling, stiff constants, reading paper" in summary
    assert "## Table 2: the coupling, literal constants, reading paper" in summary
    claims = [line for line in text.splitlines() if line.startswith(("PASS", "FAIL"))]
    assert len(claims) == 10
    # The verdicts follow from the physics (jaxunilat/README.md, "The rolling-mill coupling and
    # `reproduce`"): the ball's three claims hold (the upper-contact one only in its window);
    # the stiff coupling reproduces all three trends; the literal constants fail two of them.

    def verdicts(key):
        return [line[:4] for line in claims if key in line]

    assert verdicts("k_r lowers the amplitudes") == ["PASS"]
    assert verdicts("kappa changes amplitude and frequency") == ["PASS"]
    assert verdicts("upper racket") == ["PASS", "FAIL"]
    assert verdicts("(stiff, reading paper)") == ["PASS", "PASS", "PASS"]
    assert verdicts("(literal, reading paper)") == ["FAIL", "PASS", "FAIL"]
    assert "claims: 7 PASS, 3 FAIL" in text


def test_reproduce_bad_out(tmp_path):
    f = tmp_path / "file"
    f.write_text("x")
    assert main(["reproduce", "--out", str(f)]) == 2
    assert main(["reproduce", "--out", str(tmp_path / "no" / "dir")]) == 2
