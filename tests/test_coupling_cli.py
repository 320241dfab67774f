"""`jaxunilat simulate coupling`: the CSV contract, the plot, and one-line errors."""

import math
import os

import numpy as np
import pytest

from jaxunilat._cli._main import main


def test_simulate_coupling_csv_and_plot(tmp_path, capsys):
    out, png = tmp_path / "c.csv", tmp_path / "c.png"
    code = main(
        ["simulate", "coupling", "--example", "6", "--t1", "0.5", "--out", str(out), "--plot", str(png)]
    )
    assert code == 0
    text = capsys.readouterr().out
    assert "impacts" in text and "peak T_xi" in text
    with open(out) as f:
        assert f.readline().strip() == "t,psi_xi,dpsi_xi,psi_eta,dpsi_eta,T_xi,T_eta"
    data = np.loadtxt(out, delimiter=",", skiprows=1)
    assert data.shape == (10001, 7)
    assert data[0, 0] == 0.0 and data[-1, 0] == 0.5
    np.testing.assert_allclose(np.diff(data[:, 0]), 0.5 / 10000, rtol=1e-9)
    # Initial state ψ_ξ(0) = −δ = −arctan(Δ/l); T = κ·D on every row (κ of the stiff set).
    assert data[0, 1] == pytest.approx(-math.atan(0.005 / 13.0), rel=1e-15)
    kappa = 0.05 * 24000 * 13.0**2 / 3 * 1e5
    delta = math.atan(0.005 / 13.0)
    d_eta = np.where(data[:, 3] > delta, data[:, 3] - delta, 0) + np.where(
        data[:, 3] < -delta, data[:, 3] + delta, 0
    )
    np.testing.assert_allclose(data[:, 5], kappa * d_eta, rtol=1e-9, atol=1e-6)
    with open(png, "rb") as f:
        assert f.read(8) == b"\x89PNG\r\n\x1a\n"


def test_simulate_coupling_bad_input(tmp_path, capsys):
    assert main(["simulate", "coupling", "--example", "9"]) == 2
    assert "example = 9" in capsys.readouterr().err
    assert main(["simulate", "coupling", "--params", "soft"]) == 2
    assert main(["simulate", "coupling", "--h", "-1"]) == 2
    assert "h = -1" in capsys.readouterr().err
    # RK4 beyond its step limit, a tenth of the contact time (1.25 ms under the stiff constants).
    assert main(["simulate", "coupling", "--solver", "rk4", "--dt", "0.02"]) == 2
    assert "stability limit" in capsys.readouterr().err
    assert main(["simulate", "coupling", "--out", str(tmp_path / "missing" / "x.csv")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err


def test_literal_warns_on_stderr(capsys, tmp_path):
    code = main(
        ["simulate", "coupling", "--params", "literal", "--t1", "0.2", "--out", os.fspath(tmp_path / "l.csv")]
    )
    assert code == 0
    assert "physically absurd" in capsys.readouterr().err


def test_solver_failure_inside_a_compiled_run_is_one_line(capsys, caplog):
    """A failure raised from the compiled run (throw=True) reaches stderr as one line, without
    the traceback JAX logs for the host callback that carries it."""
    code = main(["simulate", "coupling", "--t1", "0.5", "--samples", "11", "--max-steps", "50"])
    err = capsys.readouterr().err
    assert code == 1
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert "max_steps = 50" in err
    assert not [r for r in caplog.records if r.levelname in ("ERROR", "CRITICAL")], caplog.text
