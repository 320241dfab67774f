"""Normalized sensitivities by AD through the event mode, against central finite differences.

The finite differences are of the trusted forward runs (event mode at rtol 1e-11/1e-12,
the peak located at ψ̇ = 0), evaluated without AD, at ±1e-4 in log θ.
"""

import numpy as np
import pytest

import jaxunilat as ju
from jaxunilat._cli._main import main
from jaxunilat.analysis._sensitivity import ball_sensitivity, coupling_sensitivity, format_table


def _check(result, rtol=1e-4):
    assert result.fd is not None and np.all(np.isfinite(result.table))
    err = np.abs(result.table - result.fd) / np.abs(result.fd)
    assert np.max(err) <= rtol, (err, result.table, result.fd)


@pytest.mark.slow
def test_coupling_sensitivity_matches_fd():
    """Example 6, stiff, reading A over the regular run-up [0, 1] s: peak and RMS force w.r.t. Δ, α, b, κ, k_r, h."""
    result = coupling_sensitivity(6, t1=1.0, check=True)
    assert result.meaningful
    _check(result)
    # Physics: the peak force rises with clearance, |α|, speed and κ; k_r lowers it.
    peak = dict(zip(result.parameters, result.table[0], strict=True))
    assert peak["Delta"] > 0 and peak["alpha"] > 0 and peak["b"] > 0 and peak["kappa"] > 0
    assert peak["k_r"] < 0
    # A second example with new values reuses both compiled programs.
    before = ju.trace_counts()
    again = coupling_sensitivity(4, t1=0.7)
    after = ju.trace_counts()
    assert after.get("coupling_jacobian") == before.get("coupling_jacobian")
    assert np.all(np.isfinite(again.table)) and again.meaningful


@pytest.mark.slow
def test_ball_sensitivity_matches_fd():
    """Example 2 over [0, 3] s: three apex heights and three impact times w.r.t. κ, k_r, drag and gap."""
    result = ball_sensitivity(2, t1=3.0, check=True)
    assert result.meaningful and np.all(np.isfinite(result.values))
    _check(result)
    table = dict(zip(result.outputs, result.table, strict=True))
    # k_r and drag lower the apexes; a wider gap delays the first impact about proportionally.
    assert table["apex_1"][1] < 0 and table["apex_1"][2] < 0
    assert 1.0 < table["impact_1"][3] < 1.3
    text = format_table(result)
    assert "apex_3" in text and "n/a" not in text


def test_not_meaningful_outputs_are_not_printed():
    """An output that does not happen within the horizon is reported, not printed as noise."""
    result = ball_sensitivity(2, t1=1.0)
    assert not result.meaningful
    text = format_table(result)
    assert "n/a" in text and "not meaningful" in text


def test_cli_sensitivity(capsys):
    assert main(["sensitivity", "ball", "--example", "2", "--t1", "3"]) == 0
    out = capsys.readouterr().out
    assert "impact_1" in out and "kappa" in out and "regular" in out
    assert main(["sensitivity", "ball", "--example", "9"]) == 2
    assert main(["sensitivity", "ball", "--h", "1"]) == 2


def test_an_output_missing_within_the_horizon_is_not_called_chaotic():
    """Example 2's first apex comes at 1.61 s: with t1 = 1 s the apexes do not exist, the
    gradient norm is small, and the table says the events are missing (not chaos)."""
    from jaxunilat.analysis._sensitivity import format_table

    result = ju.ball_sensitivity(2, t1=1.0)
    text = format_table(result)
    assert not result.meaningful and result.growth < 1e3
    assert "apex_1, apex_2, apex_3 did not happen within the horizon" in text
    assert "chaotic" not in text
