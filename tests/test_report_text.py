"""The human-readable fit report: numbers rounded to their uncertainty, results first,
correlations that matter, the threshold of the noise test, and gravity shown.

The rounding examples are worked by hand: the uncertainty to two significant digits,
the value to the same decimal place (half away from zero), the relative uncertainty to
two significant digits. The report checks use a `FitResult` assembled by hand (no fit
runs), so every number in it is known.
"""

from __future__ import annotations

import dataclasses
import math
import re

import numpy as np
import pytest
from jaxunilat.identify._fit._estimate import Estimate
from jaxunilat.identify._fit._outcome import InitialGuess, StartRun
from jaxunilat.identify._fit._problem import UNITS, to_z
from jaxunilat.identify._report._result import FitResult, rounded

from jaxunilat import identify

KAPPA, K_R, E, T_C = 27097.8, 0.362588, 0.935008, 1.00094e-3


@pytest.mark.parametrize(
    ("value", "stderr", "text"),
    [
        (27097.8, 434.4, "27100 +/- 430"),  # 434.4 -> 430 (tens); 27097.8 -> 27100
        (0.935008, 7.426e-6, "0.9350080 +/- 0.0000074"),  # 7.426e-6 -> 7.4e-6 (7th decimal)
        (0.362588, 0.004003, "0.3626 +/- 0.0040"),  # a trailing zero that is significant stays
        (-0.179367, 0.02743, "-0.179 +/- 0.027"),
        (9.96, 0.996, "10.0 +/- 1.0"),  # 0.996 -> 1.0: the second digit is now the tenths
        (2.675, 0.01, "2.675 +/- 0.010"),
        (2.6751, 0.013, "2.675 +/- 0.013"),
        (1.2345, 0.045, "1.235 +/- 0.045"),  # a 5 rounds away from zero, as written (not as stored)
        (1.0e8, 2.0e6, "(1.000 +/- 0.020)e+08"),  # 1e7 and beyond: one shared exponent
        (453801.0, 4.97e7, "450000 +/- 5.0e+07"),  # the value would round to 0: two digits each
        (0.305, None, "0.305 (fixed)"),
        (0.123456789, None, "0.123457 (fixed)"),  # a held value: 6 significant digits
    ],
)
def test_values_are_rounded_to_two_digits_of_their_uncertainty(value, stderr, text):
    assert rounded(value, stderr)[0] == text


def _result(**changes) -> FitResult:
    """A one-file trace result with known numbers: κ = 27097.8 ± 434.4 N/m, k_r =
    0.362588 ± 0.004003 N·s/m, e = 0.935008 ± 7.426e-6, t_c = 1.00094 ± 0.01121 ms, the
    trace's scale and level fitted; g = 9.7803 m/s²; χ² test p = 0.0116."""
    t = np.linspace(0.0, 0.2, 21)
    data = identify.Dataset(
        scene="drop", observe="trace", mass=2.7e-3, drag=0.12, x0=0.305, v0=0.0, noise=5e-4, t=t,
        x=0.305 - 0.5 * 9.7803 * t**2, gravity=9.7803, path="/data/drop.csv",
    )  # fmt: skip
    values = dict(
        kappa=KAPPA, k_r=K_R, drag=0.12, x0=0.305, v0=0.0, offset=0.0, scale=0.999928, level=2.42427e-5
    )
    errors = dict(kappa=434.4, k_r=0.004003, scale=1.409e-4, level=2.349e-5)
    free = ["kappa", "k_r", "scale", "level"]
    params = {}
    for n, v in values.items():
        half = 1.96 * errors.get(n, 0.0)
        verdict = True if n in ("kappa", "k_r") else None
        params[n] = Estimate(n, v, errors.get(n, 0.0), (v - half, v + half), UNITS[n], n not in free, verdict)
    derived = {
        "restitution": Estimate("restitution", E, 7.426e-6, (E - 1.46e-5, E + 1.46e-5), identifiable=True),
        "contact_time": Estimate(
            "contact_time", T_C, 1.121e-5, (T_C - 2.2e-5, T_C + 2.2e-5), "s", identifiable=True
        ),
    }
    corr = np.array(
        [[1.0, 0.999987, 0.0999, -0.562274], [0.999987, 1.0, 0.0, -0.561883], [0.0999, 0.0, 1.0, -0.798794],
         [-0.562274, -0.561883, -0.798794, 1.0]]
    )  # fmt: skip
    fields = dict(
        data=data, problem=None, z=to_z(values), free=free, params=params, derived=derived, correlation=corr,
        cost=1330.0, residuals=np.zeros(21), chi2=2660.17, sigma=5e-4, sigma_source="file",
        goodness={"reduced_chi2": 1.06535, "dof": 2497, "p_value": 0.0116, "consistent": True},
        converged=True, message="relative change below tolerance", iterations=17, gradient_steps=0, method="lm",
        starts=[StartRun(cost=476.9, converged=True)] * 3,
        initial=InitialGuess(restitution=0.9353, contact_time=1e-3, source="closed form (rebound heights)"),
        profile=None, rel_halfwidth=0.25, simulations=38, wall_s=6.69, used=np.ones(21, bool),
        datasets_data=[data], sigma_known=True,
    )  # fmt: skip
    fields.update(changes)
    return FitResult(**fields)


def _headers(report: str) -> list[str]:
    """The report's block headers (`[[Name]]`), in order."""
    return [line.split("]]")[0] + "]]" for line in report.splitlines() if line.startswith("[[")]


def _section(report: str, name: str) -> list[str]:
    """The lines of block `name`, its header first."""
    lines = report.splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith(f"[[{name}]]"))
    end = next((i for i in range(start + 1, len(lines)) if lines[i].startswith("[[")), len(lines))
    return lines[start:end]


def test_the_report_rounds_each_value_to_its_uncertainty():
    report = _result().report()
    results = _section(report, "Results")
    line = {row.split("=")[0].strip(): row for row in results[1:]}
    assert "27100 +/- 430 N/m" in line["kappa"] and "(1.6%)" in line["kappa"]  # 434.4 / 27097.8 = 1.603%
    assert "95% CI [26250, 27950] N/m" in line["kappa"]  # 27097.8 -/+ 851.4, to the tens
    assert "0.9350080 +/- 0.0000074" in line["e"] and "(0.00079%)" in line["e"]  # 7.426e-6 / 0.935 = 7.94e-6
    assert "1.001 +/- 0.011 ms" in line["t_c"] and "(1.1%)" in line["t_c"]  # t_c in ms
    assert "0.3626 +/- 0.0040 N*s/m" in line["k_r"]
    assert "27097.8" not in report and "434.4" not in report and "7.426e-06" not in report
    nuisance = _section(report, "Nuisance parameters")
    held = {row.split("=")[0].strip(): row for row in nuisance[1:]}
    assert held["drag"].strip() == "drag   = 0.12 (fixed) s/m"
    assert held["x0"].strip() == "x0     = 0.305 (fixed) m"
    assert "0.000024 +/- 0.000023 m" in held["level"] and "(97%)" in held["level"]  # 96.89% -> 97%


def test_results_come_first_then_nuisance_then_statistics_then_diagnostics():
    report = _result().report()
    headers = _headers(report)
    order = ["[[Data]]", "[[Results]]", "[[Nuisance parameters]]", "[[Fit Statistics]]", "[[Correlations]]"]
    assert headers[: len(order)] == order and headers[-1] == "[[Diagnostics]]", headers
    results = [row.split("=")[0].strip() for row in _section(report, "Results")[1:]]
    assert results == ["e", "t_c", "kappa", "k_r"]
    # Each of them carries its identifiability verdict on its own line, after its interval.
    for row in _section(report, "Results")[1:]:
        assert re.search(r"95% CI \[.*\].*identifiable: yes \(95% half-width [\d.]+%\)$", row), row
    assert "[[Identifiability]]" not in report and "[[Variables]]" not in report
    # How the fit ran is in [[Diagnostics]] only, not among the statistics.
    statistics = "\n".join(_section(report, "Fit Statistics"))
    diagnostics = "\n".join(_section(report, "Diagnostics"))
    for mechanics in (
        "first window",
        "first 35% of each file's span",
        "function evals",
        "LM iterations",
        "wall time",
    ):
        assert mechanics not in statistics and mechanics in diagnostics, mechanics
    assert "38 function evals" in diagnostics and "17 LM iterations" in diagnostics
    assert "chi-square of each on the first window: 953.8, 953.8, 953.8" in diagnostics  # 2 * cost


def test_a_fixed_kappa_or_k_r_shows_six_digits_and_fixed():
    result = _result(free=["kappa", "scale", "level"], correlation=np.eye(3))
    k_r = Estimate("k_r", 0.123456789, 0.0, (0.123456789,) * 2, "N*s/m", fixed=True, identifiable=False)
    result = dataclasses.replace(result, params={**result.params, "k_r": k_r})
    row = next(r for r in _section(result.report(), "Results") if r.strip().startswith("k_r"))
    assert "k_r    = 0.123457 (fixed) N*s/m" in row and "identifiable: NO (held, not fitted)" in row


def test_only_correlations_of_at_least_one_tenth_are_printed():
    section = _section(_result().report(), "Correlations")
    assert "(|C| >= 0.1" in section[0]
    shown = {re.match(r"\s+C\((.+)\) = ([-+][\d.]+)$", row).groups() for row in section[1:]}
    assert shown == {
        ("kappa, k_r", "+1.00"),  # 0.999987
        ("kappa, level", "-0.56"),
        ("k_r, level", "-0.56"),
        ("scale, level", "-0.80"),  # -0.798794
    }  # not C(kappa, scale) = 0.0999 nor C(k_r, scale) = 0
    none = _section(_result(correlation=np.eye(4)).report(), "Correlations")
    assert none[1:] == ["    none (every |C| < 0.1)"]
    # The JSON keeps every correlation, small ones too.
    matrix = _result().to_json_dict()["correlation_all"]["matrix"]
    assert matrix[0][2] == pytest.approx(0.0999) and matrix[1][2] == 0.0


def test_the_noise_test_states_its_threshold():
    line = next(x for x in _result().report().splitlines() if "fit vs noise" in x)
    assert "consistent" in line and "= 0.012" in line and "threshold 0.001" in line, line  # p = 0.0116
    failed = _result(goodness={"reduced_chi2": 1.2, "dof": 2497, "p_value": 2.0e-9, "consistent": False})
    report = failed.report()
    line = next(x for x in report.splitlines() if "fit vs noise" in x)
    assert "INCONSISTENT" in line and "= 2e-09" in line and "below the threshold 0.001" in line, line
    assert "(p = 2e-09 < 0.001)" in report  # the warning under [[Results]] says it too


def test_gravity_is_shown_in_the_data_block():
    data = _section(_result().report(), "Data")
    assert "    gravity g          = 9.7803 m/s^2" in data
    assert "    mass               = 0.0027 kg" in data


def test_json_keys_are_unchanged_by_the_report():
    doc = _result().to_json_dict()
    assert doc["parameters"]["kappa"]["value"] == KAPPA and doc["parameters"]["kappa"]["stderr"] == 434.4
    assert doc["derived"]["restitution"]["stderr"] == 7.426e-6 and doc["wall_s"] == 6.69
    assert doc["iterations"] == 17 and doc["goodness_of_fit"]["p_value"] == 0.0116
    assert math.isclose(doc["correlation"][0][1], 0.999987)


def test_the_fit_figure_names_kappa_only_where_the_data_carry_it():
    """The fit figure's title shows e always, and κ and k_r only where they are
    identifiable; otherwise it says they are not (never a number the data do not bound)."""
    from types import SimpleNamespace

    from jaxunilat.identify._report._plot import _title

    def fit(identifiable):
        return SimpleNamespace(
            params={"kappa": SimpleNamespace(value=26609.9), "k_r": SimpleNamespace(value=0.3626)},
            derived={"restitution": SimpleNamespace(value=0.935)},
            law="kelvin-voigt",
            units={"kappa": "N/m", "k_r": "N*s/m"},
            datasets_data=None,
            data=SimpleNamespace(path="data/drop_trace.csv"),
            identifiable=identifiable,
        )

    carried = _title(fit({"kappa": True, "k_r": True, "restitution": True}))
    assert "e = 0.9350" in carried and "kappa = 2.661e+04 N/m" in carried and "k_r = 0.3626 N*s/m" in carried
    withheld = _title(fit({"kappa": False, "k_r": False, "restitution": True}))
    assert "e = 0.9350" in withheld and "26" not in withheld.split("e = ")[1].split(",", 1)[1]
    assert "kappa and k_r not identifiable from these data" in withheld
